"""Error codes and the exception hierarchy of the planner core."""

import enum


class ErrorCode(str, enum.Enum):
    """The error codes of a failed request."""

    INVALID_REQUEST = 'INVALID_REQUEST'
    UNKNOWN_STATION = 'UNKNOWN_STATION'
    JOINT_MISMATCH = 'JOINT_MISMATCH'
    NOT_FINITE = 'NOT_FINITE'
    OUT_OF_LIMITS = 'OUT_OF_LIMITS'
    START_IN_COLLISION = 'START_IN_COLLISION'
    GOAL_IN_COLLISION = 'GOAL_IN_COLLISION'
    NO_PATH = 'NO_PATH'
    TIMEOUT = 'TIMEOUT'
    ROADMAP_NOT_READY = 'ROADMAP_NOT_READY'
    BUSY = 'BUSY'
    VERIFICATION_FAILED = 'VERIFICATION_FAILED'
    INTERNAL = 'INTERNAL'
    UNKNOWN_TRAJECTORY = 'UNKNOWN_TRAJECTORY'
    """A stop of a trajectory the planner did not publish (or no longer keeps)."""
    OUTSIDE_TRAJECTORY = 'OUTSIDE_TRAJECTORY'
    """A stop at a moment before a trajectory's start or after its end."""
    AT_REST = 'AT_REST'
    """A stop at a moment the trajectory is at rest: there is nothing to stop."""


class WaferPlannerError(Exception):
    """Base class of every error the package raises on purpose."""


class CellError(WaferPlannerError, ValueError):
    """A cell file that cannot be used; names the key path and the reason."""

    def __init__(self, path: str, reason: str):
        super().__init__(f'{path}: {reason}')
        self.path = path
        self.reason = reason


class PlanningError(WaferPlannerError):
    """A request that cannot be answered with a trajectory."""

    def __init__(self, code: ErrorCode, message: str):
        super().__init__(message)
        self.code = ErrorCode(code)
        self.message = message
