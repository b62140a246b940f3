"""Messages the node publishes, built from the core's results (doc/operations.md, "The node")."""

import enum
import json
from typing import Mapping, Optional, Sequence

from diagnostic_msgs.msg import DiagnosticStatus

from wafer_planner_ros.service import cdr
from wafer_planner_ros.service.requests import end_label

LEVELS = {'ok': ord(DiagnosticStatus.OK), 'warn': ord(DiagnosticStatus.WARN),
          'error': ord(DiagnosticStatus.ERROR)}


class Sent(enum.Enum):
    """What the worker hands the executor to publish: (kind, message, query number)."""

    ANSWER = enum.auto()
    """(trajectory, result): recorded together, then published in that order (a stop's:
    published, then recorded)."""
    RESULT = enum.auto()
    """An error's result alone."""
    MARKERS = enum.auto()
    """The roadmap markers of a load (query number 0)."""
    PATH = enum.auto()
    """The path markers of an answer."""


def trajectory(result, request_id: str, joint_names: Sequence[str], stamp) -> bytes:
    """
    Return the plan's samples as a serialised JointTrajectory (``frame_id`` = request id).

    ``Publisher.publish`` takes the bytes as they are; encoding them from the arrays at
    once (``cdr``) is much faster than building the point messages one by one.
    """
    return cdr.joint_trajectory(stamp.sec, stamp.nanosec, request_id, joint_names,
                                result.times, result.positions, result.velocities,
                                result.accelerations)


def plan_answer(result, request, roadmap, joint_names: Sequence[str], stamp,
                node_ms: float) -> tuple:
    """Return a successful plan's (JointTrajectory, ``~/result`` status), serialised."""
    message = '; '.join(result.warnings) or (
        f'ok: {result.start.label} -> {result.goal.label}, cycle time {result.cycle_time:.3f} s')
    values = dict(plan_values(result, roadmap, request.start, request.goal), node_ms=node_ms)
    return (trajectory(result, request.request_id, joint_names, stamp),
            result_status(request.request_id, 'warn' if result.warnings else 'ok', message,
                          values))


def result_status(request_id: str, level: str, message: str,
                  values: Mapping[str, object]) -> bytes:
    """Return the serialised ``~/result`` status: name = request id, values as strings."""
    texts = [(k, _text(v)) for k, v in values.items()]
    try:
        return cdr.diagnostic_status(LEVELS[level], request_id, message, 'wafer_planner', texts)
    except UnicodeEncodeError:  # a lone surrogate: the answer goes out with it replaced
        return cdr.diagnostic_status(LEVELS[level], _utf8(request_id), _utf8(message),
                                     'wafer_planner', [(_utf8(k), _utf8(v)) for k, v in texts])


def plan_values(result, roadmap, start, goal) -> dict:
    """Return the values of a successful result (doc/operations.md, "The node")."""
    values = {'code': 'OK', 'cycle_time': result.cycle_time,
              'initial_cycle_time': result.initial_cycle_time,
              'planning_time_ms': result.timings_ms['total']}
    values.update({f'{stage}_ms': ms for stage, ms in result.timings_ms.items()
                   if stage != 'total'})
    values.update(_ends(roadmap, start, goal))
    values.update({f'ratio_{name}': ratio
                   for name, ratio in result.verification.ratios.items()})
    values['min_clearance'] = result.min_clearance
    values['peak_jerk'] = list(result.verification.peak_jerk)
    values['peak_wafer_jerk'] = result.verification.peak_wafer_jerk
    values['certified'] = result.verification.proof.certified
    values['branches'] = result.branches
    values['load'] = result.load
    values['method'] = result.metrics.get('method', '')
    values['source'] = result.metrics.get('source', 'planned')
    values['budget'] = result.metrics.get('budget', 0.0)
    values['from_optimum'] = bool(result.metrics.get('from_optimum', False))
    if 'braking_from' in result.metrics:  # a stop: the moment it brakes from
        values['braking_from'] = result.metrics['braking_from']
    return values


def error_values(code: str, roadmap, start, goal, planning_ms: Optional[float]) -> dict:
    """Return the values of a failed request."""
    values = {'code': code}
    if planning_ms is not None:
        values['planning_time_ms'] = planning_ms
    values.update(_ends(roadmap, start, goal))
    return values


def _ends(roadmap, start, goal) -> dict:
    return {'roadmap_hash': roadmap.digest if roadmap is not None else '',
            'seed': roadmap.seed if roadmap is not None else '',
            'from': end_label(start), 'to': end_label(goal)}


def _text(value) -> str:
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, (list, tuple)):
        return json.dumps(list(value))
    return str(value)


def _utf8(text: str) -> str:
    return text.encode('utf-8', 'replace').decode('utf-8')
