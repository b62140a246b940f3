"""
Plan requests as the node receives them, read into plain values (ROS-free).

A joint request is a JointTrajectory (``header.frame_id`` = id, two points, positions in
``joint_names`` order or the robot's when the names are empty); a station request is a JSON
object ``{"id": "r17", "from": "loadport2", "to": "loadlock1"}`` whose ends may also be
three joint angles. Anything else raises ``RequestError`` with the SPEC code and a sentence
naming what is wrong; the planner then checks the values themselves (finite, limits,
collision, known station).
"""

from dataclasses import dataclass
import json
from typing import Optional, Sequence, Union

import numpy as np

from wafer_planner_ros.errors import ErrorCode

MAX_TEXT = 65536
"""Longest station request (characters) read."""

End = Union[str, np.ndarray]


@dataclass(frozen=True, eq=False)
class Request:
    """A request ready for the planner."""

    request_id: str
    start: End
    goal: End


class RequestError(Exception):
    """A request that cannot be read; ``request_id`` is what could be read ('' if nothing)."""

    def __init__(self, code: ErrorCode, message: str, request_id: str = ''):
        """Keep the code, the sentence and the id."""
        super().__init__(message)
        self.code, self.message, self.request_id = code, message, request_id


def end_label(end: Optional[End]) -> str:
    """Return a request's end as a label: a station name, or the joint values as JSON."""
    if end is None:
        return ''
    if isinstance(end, str):
        return end
    return json.dumps(np.asarray(end, float).reshape(-1).tolist())


def request_of(kind: str, message, robot_joints: Sequence[str]) -> Request:
    """
    Return the request of a received message.

    ``kind`` is 'station' (``std_msgs/String``) or 'joint' (``trajectory_msgs/
    JointTrajectory``); ``message`` is any object with those fields.
    """
    if kind == 'station':
        return station_request(message.data)
    return joint_request(message.header.frame_id, message.joint_names,
                         [point.positions for point in message.points], robot_joints)


def joint_request(request_id: str, joint_names: Sequence[str],
                  positions: Sequence[Sequence[float]], robot_joints: Sequence[str]) -> Request:
    """Return the request of a JointTrajectory's id, joint names and points' positions."""
    request_id = str(request_id)
    if not request_id:
        raise RequestError(ErrorCode.INVALID_REQUEST,
                           'the request has no id (header.frame_id is empty)')
    names = list(joint_names)
    if names:
        unknown = [n for n in names if n not in robot_joints]
        if unknown or sorted(names) != sorted(robot_joints):
            raise RequestError(ErrorCode.JOINT_MISMATCH,
                               f"joint_names {names} are not a permutation of the robot's "
                               f'{list(robot_joints)}'
                               + (f' (unknown: {unknown})' if unknown else ''), request_id)
        order = [names.index(n) for n in robot_joints]
    else:
        order = list(range(len(robot_joints)))
    if len(positions) != 2:
        raise RequestError(ErrorCode.INVALID_REQUEST,
                           f'a plan request has 2 points (start and goal), got '
                           f'{len(positions)}', request_id)
    ends = []
    for label, values in zip(('start', 'goal'), positions):
        values = np.asarray(values, dtype=float).reshape(-1)
        if len(values) != len(order):
            raise RequestError(ErrorCode.JOINT_MISMATCH,
                               f'the {label} point has {len(values)} positions; the robot has '
                               f'{len(robot_joints)} joints ({", ".join(robot_joints)})',
                               request_id)
        ends.append(values[order])
    return Request(request_id, ends[0], ends[1])


def station_request(text: str) -> Request:
    """Return the request of a station request's JSON text."""
    if len(text) > MAX_TEXT:
        raise RequestError(ErrorCode.INVALID_REQUEST,
                           f'the request is {len(text)} characters long; at most {MAX_TEXT}')
    try:
        data = json.loads(text)
    except (ValueError, RecursionError) as exc:
        raise RequestError(ErrorCode.INVALID_REQUEST,
                           f'the request is not JSON ({str(exc)[:200]})') from None
    if not isinstance(data, dict):
        raise RequestError(ErrorCode.INVALID_REQUEST,
                           f'the request must be a JSON object, got {type(data).__name__}')
    request_id = data.get('id')
    if not isinstance(request_id, str) or not request_id:
        raise RequestError(ErrorCode.INVALID_REQUEST,
                           f'the request needs a non-empty string "id", got {request_id!r}'[:300])
    ends = []
    for key in ('from', 'to'):
        if key not in data:
            raise RequestError(ErrorCode.INVALID_REQUEST, f'the request has no "{key}"',
                               request_id)
        ends.append(_end(data[key], key, request_id))
    return Request(request_id, ends[0], ends[1])


def _end(value, key: str, request_id: str) -> End:
    """Return a station name or joint angles from a JSON value."""
    if isinstance(value, str):
        return value
    if isinstance(value, list) and all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                       for v in value):
        return np.asarray(value, dtype=float)
    raise RequestError(ErrorCode.INVALID_REQUEST,
                       f'"{key}" must be a station name or a list of joint angles, got '
                       f'{json.dumps(value)[:200]}', request_id)
