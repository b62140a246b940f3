"""
Plan requests as the node receives them, read into plain values (ROS-free).

A joint request is a JointTrajectory (``header.frame_id`` = id, two points, positions in
``joint_names`` order or the robot's when the names are empty), always planned loaded; a
station request is a JSON object ``{"id": "r17", "from": "loadport2", "to": "loadlock1"}``
whose ends may also be three joint angles, with an optional ``"load"``: ``"loaded"`` (the
default: the wafer limit holds) or ``"empty"`` (no wafer on the blade: joint limits only),
and no other keys. An empty move of a joint request is a station request with joint angles.
Anything else raises ``RequestError`` with the error code and a sentence naming what is
wrong, never longer than a few hundred characters whatever the request holds: every number
is checked to be one a float holds (``NOT_FINITE`` otherwise, naming the field), and the
JSON reader itself can only fail with ``INVALID_REQUEST``. The planner then checks the
values themselves (limits, collision, known station).
"""

from dataclasses import dataclass
import json
import re
from typing import Optional, Sequence, Tuple, Union

import numpy as np

from wafer_planner_ros.cell.limits import LOADED, LOADS
from wafer_planner_ros.errors import ErrorCode
from wafer_planner_ros.service.bounded_json import JsonObject, loads, NotFinite, QUOTE, quote

MAX_TEXT = 65536
"""Longest station request (characters) read."""
MAX_ID = 256
"""Longest request id (characters)."""
MAX_NAME = 256
"""Longest station name (characters) read."""
KEYS = ('id', 'from', 'to', 'load')
"""The keys of a station request (``load`` optional)."""
STOP_KEYS = ('id', 'trajectory', 'at')
"""The keys of a stop request."""
LEADING_ID = re.compile(r'\s*\{\s*"id"\s*:\s*("(?:[^"\\\x00-\x1f]|\\.){1,%d}")' % MAX_ID)
"""A request text's id when it is the first key, read without reading the rest: its string
literal (each character, or escape, of at most ``MAX_ID``)."""


@dataclass(frozen=True)
class Moving:
    """A start in motion: a published trajectory at a moment (``"from": {...}``)."""

    trajectory: str
    """The id of the trajectory the robot follows (the request id it was published under)."""
    at: float
    """s after that trajectory's start."""

    @property
    def label(self) -> str:
        """Return the start as a label."""
        return f'{self.trajectory} at {self.at:.6g} s'


End = Union[str, np.ndarray, Moving]


@dataclass(frozen=True, eq=False)
class Request:
    """A request ready for the planner."""

    request_id: str
    start: End
    goal: End
    read_for: Tuple[str, ...] = ()
    """The robot's joint names the ends were read against (ordered, counted); () if none."""
    load: str = LOADED
    """The limit set to plan against (``cell.limits``): loaded unless the request says."""


@dataclass(frozen=True)
class StopRequest:
    """A controlled stop of a published trajectory, ready for the planner."""

    request_id: str
    trajectory: str
    """The id of the trajectory to stop (the request id it was published under)."""
    at: float
    """s after that trajectory's start."""


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
    if isinstance(end, Moving):
        return end.label
    return json.dumps(np.asarray(end, float).reshape(-1).tolist())


def request_of(kind: str, message, robot_joints: Sequence[str]) -> Request:
    """
    Return the request of a received message.

    ``kind`` is 'station' (``std_msgs/String``) or 'joint' (``trajectory_msgs/
    JointTrajectory``); ``message`` is any object with those fields. ``robot_joints`` is
    the robot's joint names, empty when the cell is not known yet (a station request's joint
    angles are then counted by the planner).
    """
    if kind == 'station':
        return station_request(message.data, robot_joints)
    return joint_request(message.header.frame_id, message.joint_names,
                         [point.positions for point in message.points], robot_joints,
                         [(point.velocities, point.accelerations)
                          for point in message.points[:1]])


def request_id_of(value) -> str:
    """Return a request id as the answer can carry it; raise RequestError when it cannot."""
    if not isinstance(value, str) or not value:
        raise RequestError(ErrorCode.INVALID_REQUEST,
                           f'the request needs a non-empty string "id", got {quote(value)}')
    _check_text(value, 'the request id', MAX_ID, '')
    return value


def leading_id(text: str) -> str:
    """
    Return the id a station request's text starts with, '' when it does not start with one.

    For a request too long or too deeply nested to read whole: its answer still carries
    the id its sender waits for, when ``"id"`` is its first key and a usable id.
    """
    found = LEADING_ID.match(text)
    if found is None:
        return ''
    try:
        return request_id_of(json.loads(found.group(1)))
    except (ValueError, RequestError):
        return ''


def joint_request(request_id: str, joint_names: Sequence[str],
                  positions: Sequence[Sequence[float]], robot_joints: Sequence[str],
                  motion: Sequence[tuple] = ()) -> Request:
    """
    Return the request of a JointTrajectory's id, joint names and points' positions.

    ``motion``: the start point's (velocities, accelerations), if given. A start in motion
    is refused (``INVALID_REQUEST``): every plan starts at rest, and one planned from rest
    for a moving robot would jump in velocity. A move is stopped or left from motion by
    naming the published trajectory it is on (``~/stop_request``).
    """
    request_id = str(request_id)
    if not request_id:
        raise RequestError(ErrorCode.INVALID_REQUEST,
                           'the request has no id (header.frame_id is empty)')
    request_id = request_id_of(request_id)
    names = list(joint_names)
    if names:
        unknown = [n for n in names if n not in robot_joints]
        if unknown or sorted(names) != sorted(robot_joints):
            raise RequestError(ErrorCode.JOINT_MISMATCH,
                               f'joint_names {quote(names)} are not a permutation of the '
                               f"robot's {quote(list(robot_joints))}"
                               + (f' (unknown: {quote(unknown)})' if unknown else ''),
                               request_id)
        order = [names.index(n) for n in robot_joints]
    else:
        order = list(range(len(robot_joints)))
    if len(positions) != 2:
        raise RequestError(ErrorCode.INVALID_REQUEST,
                           f'a plan request has 2 points (start and goal), got '
                           f'{len(positions)}', request_id)
    ends = []
    for label, values in zip(('start', 'goal'), positions):
        try:
            values = np.asarray(values, dtype=float).reshape(-1)
        except (TypeError, ValueError, OverflowError):  # only from callers other than DDS
            raise RequestError(ErrorCode.INVALID_REQUEST,
                               f'the {label} point positions are not numbers: '
                               f'{quote(values)}', request_id) from None
        if len(values) != len(order):
            raise RequestError(ErrorCode.JOINT_MISMATCH,
                               f'the {label} point has {len(values)} positions; the robot has '
                               f'{_joints(robot_joints)}', request_id)
        values = values[order]
        for joint in np.flatnonzero(~np.isfinite(values))[:1]:
            raise RequestError(ErrorCode.NOT_FINITE,
                               f'the {label} point is not finite: {robot_joints[joint]} = '
                               f'{values[joint]}', request_id)
        ends.append(values)
    for name, values in zip(('velocities', 'accelerations'), motion[0] if motion else ()):
        try:
            moving = np.any(np.asarray(values, dtype=float) != 0.0)
        except (TypeError, ValueError, OverflowError):
            moving = True
        if moving:
            raise RequestError(ErrorCode.INVALID_REQUEST,
                               f'the start point has {name} {quote(list(values))}: a plan '
                               'starts at rest (a moving robot is stopped on its path with '
                               '~/stop_request, naming the trajectory it follows)', request_id)
    return Request(request_id, ends[0], ends[1], tuple(robot_joints))


def station_request(text: str, robot_joints: Sequence[str] = ()) -> Request:
    """Return the request of a station request's JSON text (see ``request_of``)."""
    data = _json_object(text)
    request_id = request_id_of(data.get('id'))
    _only_keys(data, KEYS, 'a station request has only "id", "from", "to" and "load"',
               request_id)
    ends = []
    for key in ('from', 'to'):
        if key not in data:
            raise RequestError(ErrorCode.INVALID_REQUEST, f'the request has no "{key}"',
                               request_id)
        ends.append(_end(data[key], key, request_id, robot_joints))
    load = data.get('load', LOADED)
    if load not in LOADS:
        raise RequestError(ErrorCode.INVALID_REQUEST,
                           f'"load" must be one of {quote(list(LOADS))}, got {quote(load)}',
                           request_id)
    return Request(request_id, ends[0], ends[1], tuple(robot_joints), load)


def stop_request(text: str) -> StopRequest:
    """
    Return the stop request of its JSON text: ``{"id", "trajectory", "at"}``, nothing else.

    ``trajectory``: the id of a trajectory the node published; ``at``: seconds after its
    start, a finite number (whether it lies within the trajectory is the planner's to say).
    """
    data = _json_object(text)
    request_id = request_id_of(data.get('id'))
    _only_keys(data, STOP_KEYS, 'a stop request has only "id", "trajectory" and "at"',
               request_id)
    for key in STOP_KEYS[1:]:
        if key not in data:
            raise RequestError(ErrorCode.INVALID_REQUEST, f'the request has no "{key}"',
                               request_id)
    return StopRequest(request_id, *_moment(data, request_id))


def _json_object(text: str) -> JsonObject:
    """Return a request's JSON object; raise RequestError (with its leading id) if not one."""
    if len(text) > MAX_TEXT:
        raise RequestError(ErrorCode.INVALID_REQUEST,
                           f'the request is {len(text)} characters long; at most {MAX_TEXT}',
                           leading_id(text))
    try:
        # Numbers no float holds become markers (NOT_FINITE below, naming the field) rather
        # than raising (an integer of over 4300 digits) or overflowing later.
        data = loads(text)
    except (ValueError, RecursionError, MemoryError) as exc:
        raise RequestError(ErrorCode.INVALID_REQUEST,
                           f'the request is not JSON ({str(exc)[:QUOTE]})',
                           leading_id(text)) from None
    if not isinstance(data, dict):
        raise RequestError(ErrorCode.INVALID_REQUEST,
                           f'the request must be a JSON object, got {quote(data)}')
    return data


def _only_keys(data: JsonObject, keys: Sequence[str], which: str, request_id: str) -> None:
    """Raise RequestError for a key given twice or one not in ``keys`` (``which``: those)."""
    if data.repeated:
        raise RequestError(ErrorCode.INVALID_REQUEST,
                           f'the request has {quote(data.repeated)} more than once', request_id)
    unknown = [key for key in data if key not in keys]
    if unknown:
        # Refused, not ignored: a key the planner does not read would look obeyed.
        raise RequestError(ErrorCode.INVALID_REQUEST,
                           f'the request has unknown keys {quote(unknown)}; {which}',
                           request_id)


def _end(value, key: str, request_id: str, robot_joints: Sequence[str]) -> End:
    """Return a station name, joint angles or (``"from"`` only) a start in motion."""
    if key == 'from' and isinstance(value, dict):
        return _moving(value, request_id)
    if isinstance(value, str):
        _check_text(value, f'"{key}"', MAX_NAME, request_id)
        return value
    if isinstance(value, list) and all(
            isinstance(v, (int, float, NotFinite)) and not isinstance(v, bool) for v in value):
        if robot_joints and len(value) != len(robot_joints):
            raise RequestError(ErrorCode.JOINT_MISMATCH,
                               f'"{key}" has {len(value)} joint angles; the robot has '
                               f'{_joints(robot_joints)}', request_id)
        for index, v in enumerate(value):
            if isinstance(v, NotFinite):
                raise RequestError(ErrorCode.NOT_FINITE,
                                   f'"{key}"[{index}] is not a finite number ({v.text})',
                                   request_id)
        return np.array([float(v) for v in value], dtype=float)
    raise RequestError(ErrorCode.INVALID_REQUEST,
                       f'"{key}" must be a station name or a list of joint angles, got '
                       f'{quote(value)}', request_id)


def _moving(value: dict, request_id: str) -> Moving:
    """Return the start in motion ``{"trajectory": id, "at": seconds}`` of a "from"."""
    if sorted(value) != ['at', 'trajectory']:
        raise RequestError(ErrorCode.INVALID_REQUEST,
                           f'"from" in motion is {{"trajectory": ..., "at": ...}} and nothing '
                           f'else, got {quote(value)}', request_id)
    return Moving(*_moment(value, request_id))


def _moment(data, request_id: str) -> tuple:
    """Return (trajectory id, at) of a stop request or a start in motion, checked."""
    trajectory = data['trajectory']
    if not isinstance(trajectory, str) or not trajectory:
        raise RequestError(ErrorCode.INVALID_REQUEST,
                           f'"trajectory" must be the id of a published trajectory, got '
                           f'{quote(trajectory)}', request_id)
    _check_text(trajectory, '"trajectory"', MAX_ID, request_id)
    at = data['at']
    if isinstance(at, NotFinite):
        raise RequestError(ErrorCode.NOT_FINITE, f'"at" is {at.quoted}, not a finite number',
                           request_id)
    if isinstance(at, bool) or not isinstance(at, (int, float)):
        raise RequestError(ErrorCode.INVALID_REQUEST,
                           f'"at" must be a number of seconds, got {quote(at)}', request_id)
    return trajectory, float(at)


def _check_text(text: str, what: str, longest: int, request_id: str) -> None:
    """Refuse a string that an answer (UTF-8, NUL-terminated) could not carry as it is."""
    if len(text) > longest:
        problem = f'is {len(text)} characters long; at most {longest}'
    elif '\0' in text:
        problem = 'holds a NUL character'
    else:
        try:
            text.encode('utf-8')
            return
        except UnicodeEncodeError:
            problem = 'is not valid Unicode (a lone surrogate)'
    raise RequestError(ErrorCode.INVALID_REQUEST, f'{what} {quote(text, 60)} {problem}',
                       request_id)


def _joints(robot_joints: Sequence[str]) -> str:
    return f'{len(robot_joints)} joints ({", ".join(robot_joints)})'


def end_of_text(text: str) -> Union[str, list]:
    """
    Return a start or goal as a person types it: a station name, or 'q1,q2,q3' as floats.

    Raise ValueError, with a sentence naming the text, when it is neither.
    """
    if ',' not in text:
        return text
    try:
        return [float(v) for v in text.split(',')]
    except ValueError:
        raise ValueError(f'{quote(text.strip())} is neither a station name nor '
                         'comma-separated joint angles') from None


def with_negative_ends(argv: Sequence[str]) -> list:
    """
    Return command-line arguments in which joint angles starting with '-' stay positional.

    argparse reads '-3.1,2.0,1.8' as an unknown option. No option of the tools has a comma,
    so an argument that starts with one '-' and holds a comma gets a leading space, which
    argparse does not read as an option and ``end_of_text`` ignores.
    """
    return [' ' + a if a.startswith('-') and not a.startswith('--') and ',' in a else a
            for a in argv]
