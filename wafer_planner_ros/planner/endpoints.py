"""
A request's ends resolved: a station's configurations, or joint angles checked.

A station name gives its configuration on every elbow branch it allows;
``<station>:inside`` its pick/place pose inside its port, with the straight way out to the
port's mouth (``moves.channel``). Joint angles are checked against the position limits, the
walls and, inside a port, its tolerances. Whatever cannot be planned from is refused here
with the ``PlanningError`` code that names why.
"""

from dataclasses import dataclass, replace
from typing import Optional, Tuple

import numpy as np

from wafer_planner_ros.cell.schema import brief
from wafer_planner_ros.cell.stations import station_name
from wafer_planner_ros.errors import ErrorCode, PlanningError
from wafer_planner_ros.geometry.contacts import colliding
from wafer_planner_ros.geometry.ports import describe_deviation
from wafer_planner_ros.moves.channel import Channel

KNOWN_LISTED = 10
"""The stations an UNKNOWN_STATION message lists (then how many more there are)."""
MAX_QUOTED = 200
"""Most characters of a requested station name quoted in a message."""
AT_MOUTH = 1e-9
"""m: joint angles whose wafer centre is at most this far past a port's mouth are at the
mouth, not inside the port (rounding puts a retracted pose a hair inside)."""
CHANNEL_CHECKS = 65
"""Configurations along the way out of a port from joint angles inside it checked against
the position limits (the proof and the verification check the move itself)."""


@dataclass(frozen=True, eq=False)
class Endpoint:
    """A resolved start or goal: its label and candidate configurations."""

    label: str
    configs: Tuple[Tuple[Optional[int], np.ndarray], ...]
    """(elbow branch or None for a joint request, q)."""
    channels: Tuple[Optional[Channel], ...] = ()
    """Per configuration inside a port (a ``<station>:inside`` request, or joint angles
    inside a port): its straight way out to the port's mouth (``moves.channel``), else
    None; empty when no configuration is inside a port."""

    def channel(self, k: int) -> Optional[Channel]:
        """Return the way out of a port of configuration ``k`` (None: not inside one)."""
        return self.channels[k] if self.channels else None


def endpoint(cell, value, role: str) -> Endpoint:
    """
    Resolve a station name or three joint angles; raise PlanningError if unusable.

    ``<station>:inside`` names the station's pick/place pose inside its port; joint
    angles that put the wafer inside a port are a pose inside it too, refused when
    they break its tolerances.
    """
    if isinstance(value, str):
        return _station_end(cell, value, role)
    robot = cell.robot
    try:
        q = np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise PlanningError(ErrorCode.INVALID_REQUEST,
                            f'{role} {brief(value)} is neither a station nor joint '
                            'angles') from None
    if q.size != len(robot.joint_names):
        raise PlanningError(ErrorCode.JOINT_MISMATCH,
                            f'{role} has {q.size} joint values; the robot has '
                            f'{len(robot.joint_names)} ({", ".join(robot.joint_names)})')
    if not np.all(np.isfinite(q)):
        raise PlanningError(ErrorCode.NOT_FINITE, f'{role} {q.tolist()} is not finite')
    lower, upper = robot.limits.position.T
    for j in robot.limits.outside(q)[:1]:
        raise PlanningError(ErrorCode.OUT_OF_LIMITS,
                            f'{role} joint {robot.joint_names[j]} = {q[j]} rad is outside '
                            f'[{lower[j]}, {upper[j]}]')
    model = cell.clearance_model
    if model.clearance(q)[0] <= 0.0:
        # Every body that collides, and how: a link crossing the wall, a wafer beyond it.
        how = '; '.join(c.describe() for c in colliding(model, q)) or \
            model.contact(q).describe()
        code = ErrorCode.START_IN_COLLISION if role == 'start' else \
            ErrorCode.GOAL_IN_COLLISION
        raise PlanningError(code, f'{role} {q.tolist()} is in collision ({how})')
    label = ','.join(f'{v:g}' for v in q)
    channel = _channel_of(cell, q, role)
    return Endpoint(label, ((None, q),), () if channel is None else (channel,))


def only_branch(end: Endpoint, elbow, role: str) -> Endpoint:
    """Return ``end`` with only its configuration on the ``elbow`` branch."""
    kept = [k for k, c in enumerate(end.configs) if c[0] == elbow]
    configs = tuple(end.configs[k] for k in kept)
    if not configs:
        raise PlanningError(ErrorCode.INVALID_REQUEST,
                            f'{role} {end.label} has no elbow branch {elbow!r} (it has '
                            f'{[c[0] for c in end.configs]})')
    return replace(end, configs=configs,
                   channels=tuple(end.channels[k] for k in kept) if end.channels else ())


def mouth_label(end: Endpoint, role: str) -> str:
    """Return the label of where an end inside a port leaves it: its station's name."""
    name = station_name(end.label)
    return name if name != end.label else f'the port mouth of the {role}'


def _station_end(cell, value: str, role: str) -> Endpoint:
    """Return the end a station name (``<station>`` or ``<station>:inside``) resolves to."""
    name = station_name(value)
    station = cell.stations.get(name)
    if station is None:
        names = sorted(cell.stations)
        known = ', '.join(names[:KNOWN_LISTED]) + (
            f' and {len(names) - KNOWN_LISTED} more' if len(names) > KNOWN_LISTED else '')
        raise PlanningError(ErrorCode.UNKNOWN_STATION,
                            f'{role} {value[:MAX_QUOTED]!r} is not a station of cell '
                            f'{cell.name} ({known[:4 * MAX_QUOTED]})')
    joints = 'joints' in station.spec
    if name == value:
        return Endpoint(value, tuple((None if joints else c.elbow, c.q)
                                     for c in station.configs))
    if station.port is None:
        raise PlanningError(ErrorCode.INVALID_REQUEST,
                            f'{role} {value!r}: station {name} has no port (its '
                            'port: key in the cell file)')
    retracted = {c.elbow: c.q for c in station.configs}
    port = station.port
    return Endpoint(value, tuple((None if joints else c.elbow, c.q) for c in station.inside),
                    tuple(Channel.out_of(cell.robot.arm, c.q, port.axis, port.depth,
                                         mouth=retracted[c.elbow])
                          for c in station.inside))


def _channel_of(cell, q: np.ndarray, role: str) -> Optional[Channel]:
    """
    Return the way out of the port joint angles ``q`` are inside, None if in none.

    The wafer centre moves parallel to the port's axis, the blade keeping its heading,
    out to the port's mouth: refused when ``q`` breaks the port's tolerances, or when
    the way leaves the position limits.
    """
    ports = cell.port_model
    k = int(ports.inside(q)[0])
    if k < 0:
        return None
    how = describe_deviation(ports, q)
    if how is not None:
        raise PlanningError(ErrorCode.OUT_OF_LIMITS, f'{role} {q.tolist()}: {how}')
    port, robot = ports.ports[k], cell.robot
    length = float(port.offsets(robot.arm.wafer_center(q[None]))[0][0])
    if length <= AT_MOUTH:
        # At the mouth itself, a rounding inside (a station's own retracted pose):
        # there is no way out to take, and one of that length would end at the
        # mouth's inverse kinematics, not exactly at q.
        return None
    channel = Channel.out_of(robot.arm, q, port.axis, length)
    along = channel.configurations(np.linspace(0.0, length, CHANNEL_CHECKS))
    if len(robot.limits.outside(along)):
        raise PlanningError(ErrorCode.OUT_OF_LIMITS,
                            f'{role} {q.tolist()} is inside the port of {port.station}, '
                            f'whose way out on its elbow branch (to '
                            f'{channel.mouth.round(4).tolist()}) leaves '
                            'robot.joint_limits.position')
    return channel
