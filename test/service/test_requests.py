"""Reading requests (ROS-free): every malformed request is one bounded RequestError."""

import json

from hypothesis import given, HealthCheck, settings, strategies as st
import numpy as np
import pytest

from wafer_planner_ros.errors import ErrorCode
from wafer_planner_ros.service.bounded_json import quote
from wafer_planner_ros.service.requests import (end_label, end_of_text, joint_request,
                                                MAX_ID, RequestError, station_request,
                                                with_negative_ends)

JOINTS = ('joint_1', 'joint_2', 'joint_3')
LONGEST_MESSAGE = 700
"""No error message is longer, whatever the request (a few quotes of 200 characters)."""


def _refused(text: str, robot_joints=JOINTS) -> RequestError:
    with pytest.raises(RequestError) as caught:
        station_request(text, robot_joints)
    assert len(caught.value.message) <= LONGEST_MESSAGE
    return caught.value


def _station(end: str, request_id: str = '"x"', to: str = '"loadlock1"') -> str:
    return f'{{"id": {request_id}, "from": {end}, "to": {to}}}'


@pytest.mark.parametrize('end, field, shown', [
    ('[1' + '0' * 400 + ', 0, 0]', '"from"[0]', '401 digits'),  # the fuzzer's, once fatal
    ('[0, 1' + '0' * 5000 + ', 0]', '"from"[1]', '5001 digits'),  # past int()'s own limit
    ('[0, 0, -1' + '0' * 309 + ']', '"from"[2]', '310 digits'),
    ('[NaN, 0, 0]', '"from"[0]', 'NaN'),
    ('[0, Infinity, 0]', '"from"[1]', 'Infinity'),
    ('[0, 0, -Infinity]', '"from"[2]', '-Infinity'),
    ('[1e400, 0, 0]', '"from"[0]', '1e400'),
    ('[0, 0, 1' + '0' * 400 + '.5]', '"from"[2]', '403 characters'),
])
def test_a_number_no_float_holds_is_not_finite_naming_the_field(end, field, shown):
    error = _refused(_station(end))
    assert error.code == ErrorCode.NOT_FINITE and error.request_id == 'x'
    assert error.message == f'{field} is not a finite number ({shown})'


def test_a_station_request_is_loaded_unless_it_says_empty():
    assert station_request(_station('"loadport1"'), JOINTS).load == 'loaded'
    empty = station_request('{"id": "x", "from": [0.1, 0.2, 0.3], "to": "loadlock1:inside", '
                            '"load": "empty"}', JOINTS)
    assert empty.load == 'empty' and empty.goal == 'loadlock1:inside'
    # A joint request has no field for it: loaded, the safe side.
    assert joint_request('r1', [], [[0, 0, 0], [1, 1, 1]], JOINTS).load == 'loaded'


def test_the_largest_numbers_a_float_holds_are_read():
    request = station_request(_station('[1' + '0' * 308 + ', -1.7976931348623157e308, 0]'),
                              JOINTS)
    assert request.start.tolist() == [1e308, -1.7976931348623157e308, 0.0]
    assert json.loads(end_label(request.start)) == [1e308, -1.7976931348623157e308, 0.0]


@pytest.mark.parametrize('text, request_id, says', [
    ('[' * 60000, '', 'not JSON'),
    # Too deep to read: the id it starts with is read all the same.
    ('{"id": "x", "from": ' + '[' * 60000, 'x', 'not JSON'),
    ('{"from": "a", "id": "x", "to": ' + '[' * 60000, '', 'not JSON'),
    ('{"id": "x\\u00e9\\"", "from": ' + '[' * 60000, 'x\u00e9"', 'not JSON'),
    ('{"id": "\\ud800", "from": ' + '[' * 60000, '', 'not JSON'),
    ('{"id": ' + json.dumps('i' * (MAX_ID + 1)) + ', "from": ' + '[' * 60000, '', 'not JSON'),
    ('{"id": "x", "from": ' + '[' * 900 + ']' * 900 + ', "to": "a"}', 'x',
     '"from" must be a station name or a list of joint angles, got [[[[[[[[[...]]]]]]]]]'),
    (_station('"a"', '1' + '0' * 5000), '', 'needs a non-empty string "id", got (5001 digits)'),
    (_station('"a"', '17'), '', 'needs a non-empty string "id", got 17'),
    (_station('"a"', 'null'), '', 'needs a non-empty string "id", got null'),
    (_station('"a"', '["r1"]'), '', 'needs a non-empty string "id", got ["r1"]'),
    (_station('"a"', '""'), '', 'needs a non-empty string "id", got ""'),
    (_station('"a"', json.dumps('i' * 60000)), '', f'60000 characters long; at most {MAX_ID}'),
    (_station('"a"', '"\\ud800"'), '', 'the request id "\\ud800" is not valid Unicode'),
    (_station('"a"', '"r\\u0000"'), '', 'holds a NUL character'),
    (_station('"a\\udfff"'), 'x', '"from" "a\\udfff" is not valid Unicode'),
    (_station(json.dumps('s' * 50000)), 'x', '"from" "sss'),
    ('{"id": "x", "from": "a", "to": "b", "speed": 2}', 'x',
     'the request has unknown keys ["speed"]; a station request has only "id", "from", "to" '
     'and "load"'),
    ('{"id": "x", "from": "a", "to": "b", "load": "light"}', 'x',
     '"load" must be one of ["loaded", "empty"], got "light"'),
    ('{"id": "x", "from": "a", "to": "b", "load": null}', 'x',
     '"load" must be one of ["loaded", "empty"], got null'),
    ('{"id": "x", "from": "a", "to": "b", "to": "c"}', 'x', 'has ["to"] more than once'),
    (_station('[true, 0, 0]'), 'x', 'got [true, 0, 0]'),
    (_station('{"q": [1, 2, 3]}'), 'x', 'got {"q": [1, 2, 3]}'),
    (_station('[' + ', '.join(['"q"'] * 10000) + ']'), 'x', 'got ["q", "q", "q"'),
    ('x' * 70000, '', 'the request is 70000 characters long'),
    ('{"id": "r7", "from": "' + 'x' * 70000 + '"}', 'r7', 'the request is 70024 characters long'),
    (' \n{ "id" :"' + 'i' * MAX_ID + '", "from": "' + 'x' * 70000, 'i' * MAX_ID,
     'characters long'),
])
def test_a_malformed_station_request_is_invalid_with_a_bounded_message(text, request_id, says):
    error = _refused(text)
    assert error.code == ErrorCode.INVALID_REQUEST, error.message
    assert error.request_id == request_id
    assert says in error.message


def test_joint_angles_of_the_wrong_length_mismatch_as_a_joint_request_does():
    station = _refused(_station('[0.1, 0.2]'))
    with pytest.raises(RequestError) as joint:
        joint_request('j', [], [[0.1, 0.2], [0.1, 0.2, 0.3]], JOINTS)
    assert station.code == joint.value.code == ErrorCode.JOINT_MISMATCH
    assert station.message == ('"from" has 2 joint angles; the robot has 3 joints '
                               '(joint_1, joint_2, joint_3)')
    assert joint.value.message.endswith('the robot has 3 joints (joint_1, joint_2, joint_3)')
    assert _refused(_station('"loadport1"', to='[1, 2, 3, 4]')).message.startswith('"to" has 4')
    # Without the cell (not loaded yet) the planner counts them.
    assert station_request(_station('[0.1, 0.2]'), ()).start.tolist() == [0.1, 0.2]


@pytest.mark.parametrize('request_id, names, positions, code, says', [
    ('x' * 100000, [], [[0, 0, 0]] * 2, 'INVALID_REQUEST', '100000 characters long'),
    ('j\0', [], [[0, 0, 0]] * 2, 'INVALID_REQUEST', 'NUL'),
    ('j', ['n' * 100000] * 1000, [[0, 0, 0]] * 2, 'JOINT_MISMATCH', 'not a permutation'),
    ('j', [], [[0, float('nan'), 0], [0, 0, 0]], 'NOT_FINITE',
     'the start point is not finite: joint_2 = nan'),
    ('j', ['joint_3', 'joint_1', 'joint_2'], [[0, 0, 0], [float('-inf'), 0, 0]], 'NOT_FINITE',
     'the goal point is not finite: joint_3 = -inf'),
    ('j', [], [[0, 0, 0], [0] * 100000], 'JOINT_MISMATCH', 'has 100000 positions'),
    ('j', [], [[0, 0, 0], ['a', None, 0]], 'INVALID_REQUEST', 'not numbers: ["a", null, 0]'),
])
def test_a_malformed_joint_request_gets_a_bounded_error(request_id, names, positions, code,
                                                        says):
    with pytest.raises(RequestError) as caught:
        joint_request(request_id, names, positions, JOINTS)
    assert caught.value.code.value == code
    assert says in caught.value.message and len(caught.value.message) <= LONGEST_MESSAGE
    expected_id = '' if code == 'INVALID_REQUEST' and len(request_id) > MAX_ID or '\0' in \
        request_id else request_id
    assert caught.value.request_id == expected_id


def test_huge_finite_positions_are_left_to_the_planners_limits():
    request = joint_request('j', [], [[1e308, 0, 0], [0, 0, 0]], JOINTS)
    assert request.start.tolist() == [1e308, 0.0, 0.0]


def test_quote_is_bounded_and_never_fails():
    deep = []
    for _ in range(100000):
        deep = [deep]
    assert quote(deep) == '[[[[[[[[[...]]]]]]]]]'
    assert len(quote(['x' * 10 ** 6] * 1000)) <= 210
    assert quote(10 ** 5000) == '(5001 digits)'
    assert quote({'k': float('nan'), 'b': b'x'}) == '{"k": NaN, "b": <bytes>}'
    assert quote('\ud800') == '"\\ud800"'


numbers = st.one_of(st.integers(), st.floats(allow_nan=True, allow_infinity=True),
                    st.integers(min_value=300, max_value=6000).map(lambda n: '9' * n))
leaves = st.one_of(st.none(), st.booleans(), numbers, st.text(max_size=20),
                   st.sampled_from(['loadport1', 'loadlock2']))
values = st.recursive(leaves, lambda inner: st.one_of(
    st.lists(inner, max_size=5), st.dictionaries(st.text(max_size=5), inner, max_size=3)),
    max_leaves=12)
objects = st.dictionaries(st.sampled_from(['id', 'from', 'to', 'extra']), values, max_size=4)


def _text(value) -> str:
    """Return JSON in which the '999…' strings stand for huge bare integers."""
    if isinstance(value, str) and value.startswith('999') and set(value) == {'9'}:
        return value
    if isinstance(value, list):
        return '[' + ', '.join(_text(v) for v in value) + ']'
    if isinstance(value, dict):
        return '{' + ', '.join(f'{json.dumps(k)}: {_text(v)}' for k, v in value.items()) + '}'
    return json.dumps(value, allow_nan=True)


@settings(max_examples=400, deadline=None, derandomize=True,
          suppress_health_check=list(HealthCheck))
@given(st.one_of(objects.map(_text), values.map(_text), st.text(max_size=200),
                 st.integers(1, 3000).map(lambda n: '[' * n),
                 st.integers(1, 3000).map(lambda n: '{"id": "x", "from": ' + '[' * n)))
def test_any_text_is_a_request_or_one_request_error(text):
    try:
        request = station_request(text, JOINTS)
    except RequestError as error:
        assert isinstance(error.code, ErrorCode) and len(error.message) <= LONGEST_MESSAGE
        assert len(error.request_id) <= MAX_ID
        return
    assert request.request_id and len(request.request_id) <= MAX_ID
    for end in (request.start, request.goal):
        assert isinstance(end, str) or (end.shape == (3,) and np.all(np.isfinite(end)))
        end_label(end).encode('utf-8')  # an answer can carry it


def test_negative_joint_angles_stay_positional_and_read_as_angles():
    argv = ['-2.43,-1.58,-0.70', 'loadlock1', '--json', '-', '--sample-period', '-0.01',
            '--id=a,b', '-h']
    marked = with_negative_ends(argv)
    assert marked == [' -2.43,-1.58,-0.70'] + argv[1:]  # only the joint angles change
    assert end_of_text(marked[0]) == [-2.43, -1.58, -0.70]


class _Point:
    def __init__(self, positions, velocities=(), accelerations=()):
        self.positions, self.velocities, self.accelerations = positions, velocities, accelerations


class _Header:
    frame_id = 'm1'


class _Message:
    header = _Header()
    joint_names = []

    def __init__(self, *points):
        self.points = list(points)


def test_a_joint_request_starting_in_motion_is_refused_not_planned_from_rest():
    from wafer_planner_ros.errors import ErrorCode
    from wafer_planner_ros.service.requests import request_of, RequestError
    joints = ('shoulder', 'elbow', 'wrist')
    goal = _Point([0.2, 0.3, 0.4])
    start = _Point([0.1, 0.2, 0.3], [0.0] * 3, [0.0] * 3)
    at_rest = request_of('joint', _Message(start, goal), joints)
    assert at_rest.request_id == 'm1'
    for moving in (_Point([0.1, 0.2, 0.3], [0.0, 0.5, 0.0]),
                   _Point([0.1, 0.2, 0.3], [], [0.0, 0.0, -1.0])):
        with pytest.raises(RequestError) as raised:
            request_of('joint', _Message(moving, goal), joints)
        assert raised.value.code is ErrorCode.INVALID_REQUEST
        assert 'starts at rest' in raised.value.message and raised.value.request_id == 'm1'
