"""The planning node in-process: requests, answers, markers, services, bad input, load."""

from diagnostic_msgs.msg import DiagnosticStatus
from independent import check
from node_harness import values, wait_for
import numpy as np
import pytest
import rclpy
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import String

from wafer_planner_ros.cache import load_or_build
from wafer_planner_ros.planner import Planner
from wafer_planner_ros.report import plan_json, roadmap_json


def test_station_request_publishes_the_core_planners_trajectory(harness, default_cell,
                                                                roadmap_cache):
    harness.send_stations({'id': 's1', 'from': 'loadport2', 'to': 'loadlock1'})
    result = harness.result('s1')
    assert result.level == DiagnosticStatus.OK, result.message
    got = values(result)
    assert got['code'] == 'OK' and got['from'] == 'loadport2' and got['to'] == 'loadlock1'
    wait_for(lambda: any(t.header.frame_id == 's1' for t in harness.trajectories), 10)
    trajectory = next(t for t in harness.trajectories if t.header.frame_id == 's1')
    cached = load_or_build(default_cell, cache_dir=roadmap_cache)
    core = Planner(default_cell, cached.roadmap).plan('loadport2', 'loadlock1')
    assert float(got['cycle_time']) == pytest.approx(core.cycle_time, rel=1e-12)
    assert got['roadmap_hash'] == cached.roadmap.digest
    assert list(trajectory.joint_names) == list(default_cell.robot.joint_names)
    positions = np.array([p.positions for p in trajectory.points])
    times = np.array([p.time_from_start.sec + 1e-9 * p.time_from_start.nanosec
                      for p in trajectory.points])
    assert np.allclose(positions, core.positions, rtol=0, atol=1e-12)
    assert np.allclose(times, core.times, rtol=0, atol=1e-9)
    assert np.array_equal(positions[0], core.start_q)
    check(default_cell, plan_json(core, roadmap_json(cached), default_cell.robot.joint_names),
          core.start_q, core.goal_q)


def test_joint_request_in_any_joint_order(harness, default_cell):
    start = default_cell.stations['loadport1'].configs[0].q
    goal = default_cell.stations['loadlock2'].configs[0].q
    names = list(default_cell.robot.joint_names)
    order = [2, 0, 1]
    harness.send_joints('j1', start[order], goal[order], [names[i] for i in order])
    result = harness.result('j1')
    assert result.level == DiagnosticStatus.OK, result.message
    wait_for(lambda: any(t.header.frame_id == 'j1' for t in harness.trajectories), 10)
    trajectory = next(t for t in harness.trajectories if t.header.frame_id == 'j1')
    assert np.array_equal(np.array(trajectory.points[0].positions), start)
    assert np.array_equal(np.array(trajectory.points[-1].positions), goal)


@pytest.mark.parametrize('kind, request_id, payload, code', [
    ('stations', 'b1', {'id': 'b1', 'from': 'loadport9', 'to': 'loadlock1'}, 'UNKNOWN_STATION'),
    ('stations', 'b2', {'id': 'b2', 'from': 'loadport1'}, 'INVALID_REQUEST'),
    ('stations', '', {'from': 'loadport1', 'to': 'loadlock1'}, 'INVALID_REQUEST'),
    ('stations', 'b4', {'id': 'b4', 'from': [0.1, 0.2], 'to': 'loadlock1'}, 'JOINT_MISMATCH'),
    ('stations', 'b5', {'id': 'b5', 'from': [0.0, 3.5, 0.0], 'to': 'loadlock1'},
     'OUT_OF_LIMITS'),
    ('stations', 'b6', {'id': 'b6', 'from': [-1.5707963, 0.0, 0.0], 'to': 'loadlock1'},
     'START_IN_COLLISION'),
    ('stations', 'b7', {'id': 'b7', 'from': 'loadport1', 'to': 'loadport1'},
     'INVALID_REQUEST'),
    ('joints', 'b8', ([0.1, 0.2], [0.1, 0.2, 0.3]), 'JOINT_MISMATCH'),
    ('joints', 'b9', ([0.1, float('nan'), 0.0], [0.1, 0.2, 0.3]), 'NOT_FINITE'),
    ('joints', 'b10', ([0.1, float('inf'), 0.0], [0.1, 0.2, 0.3]), 'NOT_FINITE'),
    ('names', 'b11', ['joint_1', 'joint_2', 'elbow_x'], 'JOINT_MISMATCH'),
    ('points', 'b12', 0, 'INVALID_REQUEST'),
    ('points', 'b13', 1, 'INVALID_REQUEST'),
    ('points', 'b14', 3, 'INVALID_REQUEST'),
    ('points', 'b15', 100000, 'INVALID_REQUEST'),
    ('raw', '', 'not json {', 'INVALID_REQUEST'),
    ('raw', '', '', 'INVALID_REQUEST'),
    ('raw', '', '[1, 2, 3]', 'INVALID_REQUEST'),
    ('raw', '', 'x' * 200000, 'INVALID_REQUEST'),
])
def test_every_bad_input_gets_one_error_and_the_node_serves_on(
        harness, kind, request_id, payload, code):
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
    before = len(harness.results)
    if kind == 'stations':
        harness.send_stations(payload)
    elif kind == 'joints':
        harness.send_joints(request_id, *payload)
    elif kind == 'raw':
        harness.station_pub.publish(String(data=payload))
    else:
        msg = JointTrajectory()
        msg.header.frame_id = request_id
        if kind == 'names':
            msg.joint_names = payload
            msg.points = [JointTrajectoryPoint(positions=[0.0, 0.0, 0.0])] * 2
        else:
            msg.points = [JointTrajectoryPoint(positions=[0.0, 1.0, 0.0])] * payload
        harness.joint_pub.publish(msg)
    wait_for(lambda: len(harness.results) > before, 30)
    result = harness.results[before]
    assert result.name == request_id
    assert result.level == DiagnosticStatus.ERROR
    assert values(result)['code'] == code, result.message
    assert result.message.startswith(code)
    # Exactly one answer, and the node still plans.
    harness.send_stations({'id': f'after-{request_id or kind}-{code}', 'from': 'loadport3',
                           'to': 'loadlock2'})
    after = harness.result(f'after-{request_id or kind}-{code}')
    assert after.level == DiagnosticStatus.OK
    assert sum(1 for r in harness.results[before:] if r.name == request_id) == 1


def test_late_subscriber_gets_the_roadmap_markers(harness, default_cell):
    inbox = harness.subscribe_markers()
    wait_for(lambda: inbox, 20)
    namespaces = {m.ns for m in inbox[0].markers}
    assert {'enclosure', 'stations', 'station_labels', 'roadmap_nodes', 'roadmap_edges'} \
        <= namespaces
    labels = {m.text for m in inbox[0].markers if m.ns == 'station_labels'}
    assert {'loadport1 (+1)', 'loadport1 (-1)'} <= labels
    nodes = next(m for m in inbox[0].markers if m.ns == 'roadmap_nodes')
    assert len(nodes.points) == harness.status()['nodes']
    assert all(m.header.frame_id == 'efem' for m in inbox[0].markers)


def test_services_answer(harness):
    status = harness.status()
    for key in ('ready', 'nodes', 'edges', 'hash', 'seed', 'queue', 'served', 'failed',
                'last_error'):
        assert key in status
    assert status['ready'] and status['nodes'] == 1510 and status['edges'] == 40885
    rebuilt = harness.call('rebuild_roadmap')
    assert rebuilt.success, rebuilt.message
    # While it runs: status answers, a second rebuild is refused, requests are not ready.
    during = harness.status()
    assert not during['ready']
    assert not harness.call('rebuild_roadmap').success
    harness.send_stations({'id': 'during-rebuild', 'from': 'loadport1', 'to': 'loadlock1'})
    assert values(harness.result('during-rebuild'))['code'] == 'ROADMAP_NOT_READY'
    wait_for(lambda: harness.status()['ready'], 120)
    assert harness.status()['hash'] == status['hash']  # same parameters, same roadmap
    harness.send_stations({'id': 'after-rebuild', 'from': 'loadport1', 'to': 'loadlock1'})
    assert harness.result('after-rebuild').level == DiagnosticStatus.OK


def test_parameters_are_checked(harness):
    from rclpy.parameter import Parameter
    node = harness.node
    bad = node.set_parameters([Parameter('roadmap.nodes', value=-5)])[0]
    assert not bad.successful and 'roadmap.nodes' in bad.reason
    bad = node.set_parameters([Parameter('planning.timeout', value=float('nan'))])[0]
    assert not bad.successful and 'planning.timeout' in bad.reason
    good = node.set_parameters([Parameter('trajectory.sample_period', value=0.02)])[0]
    assert good.successful
    harness.send_stations({'id': 'p1', 'from': 'loadport1', 'to': 'loadlock1'})
    harness.result('p1')
    wait_for(lambda: any(t.header.frame_id == 'p1' for t in harness.trajectories), 10)
    trajectory = next(t for t in harness.trajectories if t.header.frame_id == 'p1')
    step = trajectory.points[1].time_from_start
    assert step.sec + 1e-9 * step.nanosec == pytest.approx(0.02)
    node.set_parameters([Parameter('trajectory.sample_period', value=0.01)])


def test_timeout_and_busy(harness):
    from rclpy.parameter import Parameter
    node = harness.node
    node.set_parameters([Parameter('planning.timeout', value=0.01)])
    harness.send_stations({'id': 't1', 'from': 'loadport1', 'to': 'loadlock1'})
    assert values(harness.result('t1'))['code'] == 'TIMEOUT'
    node.set_parameters([Parameter('planning.timeout', value=30.0),
                         Parameter('planning.max_queue', value=1)])
    ids = [f'q{k}' for k in range(12)]
    for request_id in ids:
        harness.send_stations({'id': request_id, 'from': 'loadport1', 'to': 'loadlock1'})
    codes = [values(harness.result(i))['code'] for i in ids]
    assert 'BUSY' in codes and 'OK' in codes
    assert len([r for r in harness.results if r.name in ids]) == len(ids)
    node.set_parameters([Parameter('planning.max_queue', value=32)])


def test_bad_parameter_at_start_up_is_rejected(tmp_path):
    from rclpy.exceptions import ParameterException
    from rclpy.parameter import Parameter
    from wafer_planner_ros.node.planner_node import WaferPlannerNode
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        with pytest.raises((ValueError, ParameterException), match='roadmap.nodes'):
            WaferPlannerNode(context=context,
                             parameter_overrides=[Parameter('roadmap.nodes', value=3)])
    finally:
        rclpy.try_shutdown(context=context)


def test_random_requests_each_get_exactly_one_result(harness):
    from hypothesis import given, HealthCheck, settings, strategies as st
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
    names = ['joint_1', 'joint_2', 'joint_3', 'shoulder', 'elbow', 'wrist', '']
    floats = st.floats(allow_nan=True, allow_infinity=True, width=64)
    point = st.lists(floats, max_size=5)
    trajectories = st.tuples(st.text(max_size=12), st.lists(st.sampled_from(names), max_size=4),
                             st.lists(point, max_size=4))
    value = st.one_of(st.none(), st.integers(), floats, st.text(max_size=10),
                      st.sampled_from(['loadport1', 'loadlock2', 'loadport3']),
                      st.lists(floats, max_size=4))
    objects = st.dictionaries(st.sampled_from(['id', 'from', 'to', 'extra']), value)
    texts = st.one_of(st.text(max_size=300), objects.map(lambda d: _json(d)))
    sent = [0]
    before = len(harness.results)

    @settings(max_examples=80, deadline=None, derandomize=True,
              suppress_health_check=list(HealthCheck))
    @given(st.one_of(trajectories, texts))
    def send(request):
        count = len(harness.results)
        if isinstance(request, tuple):
            request_id, joint_names, points = request
            msg = JointTrajectory(joint_names=joint_names)
            msg.header.frame_id = request_id
            msg.points = [JointTrajectoryPoint(positions=p) for p in points]
            harness.joint_pub.publish(msg)
        else:
            harness.station_pub.publish(String(data=request))
        sent[0] += 1
        wait_for(lambda: len(harness.results) > count, 60)

    send()
    harness.send_stations({'id': 'alive', 'from': 'loadport2', 'to': 'loadlock2'})
    assert harness.result('alive').level == DiagnosticStatus.OK
    assert len(harness.results) - before == sent[0] + 1  # exactly one answer each


def _json(data) -> str:
    import json
    return json.dumps(data, allow_nan=True)


def test_a_cell_that_cannot_be_loaded_is_reported_and_requests_are_not_ready(tmp_path):
    from rclpy.parameter import Parameter
    from wafer_planner_ros.node.planner_node import WaferPlannerNode
    context = rclpy.Context()
    rclpy.init(context=context)
    missing = tmp_path / 'missing.yaml'
    node = WaferPlannerNode(context=context, parameter_overrides=[
        Parameter('cell_file', value=str(missing)),
        Parameter('recording.directory', value=str(tmp_path / 'recordings'))])
    try:
        wait_for(lambda: node.status()['busy_with'] is None and node.status()['last_error'],
                 30)
        status = node.status()
        assert not status['ready'] and str(missing) in status['last_error']
        answers = []
        node._send = lambda *items: answers.extend(items)  # catch what would be published
        node._on_station_request(serialize_message(
            String(data='{"id": "n1", "from": "loadport1", "to": "loadlock1"}')), {})
        (kind, data, number), = answers
        result = deserialize_message(data, DiagnosticStatus)
        assert kind == 'result' and result.name == 'n1' and number == 1
        assert values(result)['code'] == 'ROADMAP_NOT_READY' and str(missing) in result.message
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=context)
