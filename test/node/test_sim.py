"""The simulated arm: its controller model (ROS-free) and the node ``wafer_sim`` over DDS."""

import threading
import time

import numpy as np
import pytest

from wafer_planner_ros.planner import Planner
from wafer_planner_ros.service.execution import samples_of, TrajectoryFollower
from wafer_planner_ros.service.execution import TrajectoryRefused

NAMES = ('shoulder', 'elbow', 'wrist')  # the default cell's joints


@pytest.fixture(scope='module')
def planned(default_cell, default_roadmap):
    """Return a planned move of the default cell, loadport1 -> loadlock2 (10 ms samples)."""
    return Planner(default_cell, default_roadmap).plan('loadport1', 'loadlock2')


@pytest.fixture(scope='module')
def robot(default_cell):
    """Return the default cell's robot."""
    assert tuple(default_cell.robot.joint_names) == NAMES
    return default_cell.robot


def _samples_of(result):
    return samples_of(NAMES, NAMES, result.times, result.positions, result.velocities,
                      result.accelerations)


def _quintics(rng, joints=3):
    """Return random quintic polynomials (coefficients, one row per joint) and their values."""
    coefficients = rng.normal(size=(joints, 6))

    def at(t):
        t = np.asarray(t, float)[..., None]
        powers = [t ** k for k in range(6)]
        q = sum(c * p for c, p in zip(coefficients.T, powers))
        qd = sum(k * c * powers[k - 1] for k, c in enumerate(coefficients.T) if k)
        qdd = sum(k * (k - 1) * c * powers[k - 2] for k, c in enumerate(coefficients.T)
                  if k > 1)
        return q, qd, qdd
    return at


def _resting(times, q, qd, qdd):
    """Return the samples with the last point at rest (the controller refuses others)."""
    qd = qd.copy()
    qd[-1] = 0.0
    return samples_of(NAMES, NAMES, times, q, qd, qdd)


# ----------------------------------------------------------------- the controller model


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_the_state_is_exact_at_the_samples_and_the_controllers_quintic_between(robot, seed):
    rng = np.random.default_rng(seed)
    at = _quintics(rng)
    times = np.concatenate([[0.0], np.cumsum(rng.uniform(0.01, 0.3, 12))])
    q, qd, qdd = at(times)
    follower = TrajectoryFollower(robot, q[0])
    start = 5.0
    follower.replace(start, _resting(times, q, qd, qdd), now=4.0)
    state = follower.state(start + times[:-1])
    for got, want in zip(state, (q[:-1], qd[:-1], qdd[:-1])):
        assert np.max(np.abs(got - want)) < 1e-9
    # A quintic through each segment's two ends (position, velocity, acceleration)
    # reproduces a quintic polynomial everywhere: the controller's interpolation.
    t = rng.uniform(times[0], times[-2], 200)
    for got, want in zip(follower.state(start + t), at(t)):
        assert np.max(np.abs(got - want)) < 1e-7 * max(1.0, np.max(np.abs(want)))


def test_positions_alone_are_interpolated_linearly_and_velocities_cubically(robot):
    times = np.array([0.0, 1.0, 3.0])
    q = np.array([[0.0, 0.0, 0.0], [1.0, 2.0, 3.0], [1.0, 2.0, 5.0]])
    follower = TrajectoryFollower(robot, q[0])
    follower.replace(0.0, samples_of(NAMES, NAMES, times, q, [[]] * 3, [[]] * 3), now=0.0)
    assert np.allclose(follower.state(2.0).q, [1.0, 2.0, 4.0])
    assert np.allclose(follower.state(2.0).qd, [0.0, 0.0, 1.0])
    # A cubic through positions and velocities: a cubic polynomial exactly.
    cubic = np.array([0.3, -1.0, 0.5, 0.2])
    t = np.array([0.0, 0.7, 2.0])
    qs = np.polyval(cubic[::-1], t)[:, None] * [1.0, 2.0, -1.0]
    vs = np.polyval(np.polyder(cubic[::-1]), t)[:, None] * [1.0, 2.0, -1.0]
    vs[-1] = 0.0  # at rest at the end: the last segment is another cubic
    follower = TrajectoryFollower(robot, qs[0])
    follower.replace(0.0, samples_of(NAMES, NAMES, t, qs, vs, [[]] * 3), now=0.0)
    assert np.allclose(follower.state(0.3).q, np.polyval(cubic[::-1], 0.3) * np.array(
        [1.0, 2.0, -1.0]), atol=1e-12)


def test_it_holds_its_start_until_a_trajectory_comes_and_the_last_point_after_it(robot):
    follower = TrajectoryFollower(robot, [0.1, 0.2, 0.3])
    assert np.array_equal(follower.state(-1e9).q, [0.1, 0.2, 0.3])
    assert not np.any(follower.state(123.0).qd)
    times = np.array([0.0, 0.5, 1.0])
    q = np.array([[0.1, 0.2, 0.3], [0.2, 0.1, 0.3], [0.3, 0.0, 0.3]])
    follower.replace(None, samples_of(NAMES, NAMES, times, q, np.zeros((3, 3)),
                                      np.zeros((3, 3))), now=10.0)  # zero stamp: now
    assert follower.end_time() == 11.0
    for t in (11.0, 11.5, 1e6):
        state = follower.state(t)
        assert np.array_equal(state.q, q[-1])
        assert not np.any(state.qd) and not np.any(state.qdd)


@pytest.mark.parametrize('lead_in', [0.0, 0.25], ids=['first-point-at-0', 'lead-in'])
def test_a_replacement_between_samples_is_continuous_to_the_acceleration(robot, planned,
                                                                         lead_in):
    follower = TrajectoryFollower(robot, planned.positions[0])
    follower.replace(100.0, _samples_of(planned), now=100.0)
    handoff = 100.0 + 0.4373  # between two 10 ms samples, the arm moving
    at_handoff = follower.state(handoff)
    assert np.max(np.abs(at_handoff.qd)) > 0.1
    # A new trajectory: with its first point at t = 0 where the arm is (as a plan from the
    # current state), or with its first point later, which the controller leads in to.
    times = np.array([0.0, 0.3, 0.6]) + lead_in
    q = at_handoff.q + np.array([[0.0, 0.0, 0.0], [0.05, -0.02, 0.01], [0.08, -0.03, 0.0]])
    qd = np.array([at_handoff.qd, [0.1, -0.05, 0.0], [0.0, 0.0, 0.0]])
    qdd = np.array([at_handoff.qdd, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    if lead_in:
        q[0] += 0.01  # not where the arm is: the lead-in gets there
    jump = follower.replace(handoff, samples_of(NAMES, NAMES, times, q, qd, qdd),
                            now=handoff - 0.2)  # sent ahead: the current goes on until then
    assert jump == 0.0
    for eps in (1e-6, 1e-8):
        before, after = follower.state(handoff - eps), follower.state(handoff + eps)
        for b, a, at, scale in zip(before, after, at_handoff, (1.0, 1e2, 1e4)):
            assert np.max(np.abs(b - at)) < scale * eps * 10
            assert np.max(np.abs(a - at)) < scale * eps * 10
    assert np.allclose(follower.state(handoff + lead_in).q, q[0], atol=1e-12)
    assert np.array_equal(follower.state(handoff + lead_in + 1.0).q, q[-1])


def test_a_start_in_the_future_waits_and_a_later_trajectory_replaces_one_waiting(robot):
    follower = TrajectoryFollower(robot, [0.0, 0.0, 0.0])
    rest = np.zeros((2, 3))
    moved = samples_of(NAMES, NAMES, [0.0, 1.0], [[0.0] * 3, [1.0] * 3], rest, rest)
    follower.replace(5.0, moved, now=1.0)
    assert np.array_equal(follower.state(4.9).q, [0.0, 0.0, 0.0])
    assert np.allclose(follower.state(6.0).q, [1.0] * 3)
    other = samples_of(NAMES, NAMES, [0.0, 1.0], [[0.0] * 3, [-1.0] * 3], rest, rest)
    follower.replace(None, other, now=2.0)
    assert np.allclose(follower.state(6.0).q, [-1.0] * 3)  # the waiting one never starts


@pytest.mark.parametrize('case, message', [
    ({'names': ('shoulder', 'elbow', 'hand')}, 'not the arm'),
    ({'names': ('shoulder', 'elbow')}, 'not the arm'),
    ({'names': ('shoulder', 'elbow', 'elbow')}, 'not the arm'),
    ({'times': [0.0, 0.5, 0.5]}, 'do not ascend'),
    ({'times': [0.0, 0.7, 0.5]}, 'do not ascend'),
    ({'times': [-0.1, 0.5, 1.0]}, 'negative'),
    ({'positions': [[0.0] * 3, [0.1] * 2, [0.2] * 3]}, 'point 1 has 2 positions'),
    ({'velocities': [[0.0] * 3, [0.1] * 4, [0.0] * 3]}, 'point 1 has 4 velocities'),
    ({'positions': [[0.0] * 3, [np.nan] * 3, [0.2] * 3]}, 'not finite'),
    ({'velocities': [[0.0] * 3, [0.1] * 3, [0.1] * 3]}, 'not at rest'),
    ({'times': [], 'positions': []}, 'no points'),
])
def test_a_trajectory_the_controller_refuses_is_refused_and_changes_nothing(
        robot, case, message):
    follower = TrajectoryFollower(robot, [0.0, 0.0, 0.0])
    given = {'names': NAMES, 'times': [0.0, 0.5, 1.0],
             'positions': [[0.0] * 3, [0.1] * 3, [0.2] * 3],
             'velocities': [[0.0] * 3, [0.1] * 3, [0.0] * 3]}
    given.update(case)
    with pytest.raises(TrajectoryRefused, match=message):
        samples = samples_of(NAMES, given['names'], given['times'], given['positions'],
                             given['velocities'])
        follower.replace(0.0, samples, now=0.0)
    assert np.array_equal(follower.state(0.7).q, [0.0, 0.0, 0.0])


def test_joints_in_another_order_are_put_in_the_arms_and_an_ended_one_is_refused(robot):
    follower = TrajectoryFollower(robot, [0.0, 0.0, 0.0])
    samples = samples_of(NAMES, ('wrist', 'shoulder', 'elbow'), [0.0, 1.0],
                         [[0.0, 0.0, 0.0], [3.0, 1.0, 2.0]], [[0.0] * 3] * 2)
    with pytest.raises(TrajectoryRefused, match='before now'):
        follower.replace(1.0, samples, now=2.5)
    follower.replace(1.0, samples, now=1.5)  # begun already: followed from where it is now
    assert np.allclose(follower.state(3.0).q, [1.0, 2.0, 3.0])


def test_executing_a_plan_follows_its_curve_and_keeps_the_wafer_limit(robot, planned):
    follower = TrajectoryFollower(robot, planned.positions[0])
    assert follower.replace(None, _samples_of(planned), now=0.0) == 0.0
    t = np.arange(0.0, planned.cycle_time + 0.2, 0.01) + 0.0037  # 100 Hz, off the samples
    q = follower.state(t).q
    want = planned.trajectory.evaluate(np.minimum(t, planned.trajectory.duration))
    assert np.max(np.abs(q - want)) < 1e-6  # the interpolation of 10 ms samples
    ratios = [follower.wafer(s).ratio for s in t]
    assert 0.5 < max(ratios) <= 1.0 + 1e-3
    ax, ay = robot.arm.wafer_acceleration_xy(*follower.state(t[100]))
    assert np.allclose(follower.wafer(t[100]).acceleration, [ax, ay])


# ----------------------------------------------------------------- the node over DDS


class _Watcher:
    """A peer of ``wafer_sim``: publishes trajectories, keeps what the sim publishes."""

    def __init__(self, context, sim):
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.node import Node
        from sensor_msgs.msg import JointState
        from std_msgs.msg import Float64MultiArray
        from trajectory_msgs.msg import JointTrajectory
        from visualization_msgs.msg import MarkerArray
        from wafer_planner_ros.node.sim import LATCHED, RELIABLE
        self.node = Node('sim_watcher', context=context)
        self.joints, self.wafer, self.markers = [], [], []
        self.node.create_subscription(JointState, '/joint_states', self.joints.append, 100)
        self.node.create_subscription(Float64MultiArray, '/wafer_sim/wafer_acceleration',
                                      self.wafer.append, 100)
        self.node.create_subscription(MarkerArray, '/wafer_sim/arm_markers',
                                      self.markers.append, LATCHED)
        self.trajectory_pub = self.node.create_publisher(
            JointTrajectory, '/wafer_planner/trajectory', RELIABLE)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(sim)
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()

    def close(self) -> None:
        self.executor.shutdown()
        self.thread.join(timeout=10)
        self.node.destroy_node()


@pytest.fixture(scope='module')
def sim(tmp_path_factory):
    """Yield (the sim node, a watcher) on a private context, in a DDS domain of the run."""
    import rclpy
    from node_harness import isolate_dds, wait_for
    from wafer_planner_ros.node.sim import SimulatedArm
    isolate_dds(tmp_path_factory.mktemp('dds'))
    context = rclpy.Context()
    rclpy.init(context=context)
    node = SimulatedArm(context=context)
    watcher = _Watcher(context, node)
    wait_for(lambda: watcher.trajectory_pub.get_subscription_count() > 0
             and watcher.joints and watcher.markers, 20.0)
    yield node, watcher
    watcher.close()
    node.destroy_node()
    rclpy.try_shutdown(context=context)


def _seconds(stamp) -> float:
    return stamp.sec + 1e-9 * stamp.nanosec


def test_the_sim_holds_its_start_and_publishes_state_wafer_and_markers(sim, default_cell):
    node, watcher = sim
    start = default_cell.stations['loadport1'].configs[0].q
    state = watcher.joints[-1]
    assert tuple(state.name) == NAMES and len(state.effort) == 0
    assert np.array_equal(state.position, start) and not np.any(state.velocity)
    assert list(watcher.wafer[-1].data) == [0.0, 0.0, 0.0, 0.0]
    assert watcher.wafer[-1].layout.dim[0].label == 'x,y,norm,ratio'
    spaces = {m.ns for m in watcher.markers[-1].markers}
    assert spaces == {'arm', 'arm_wafer', 'arm_link_ends'}
    assert {m.header.frame_id for m in watcher.markers[-1].markers} == {'efem'}


def test_the_sim_follows_a_planned_trajectory_and_survives_malformed_ones(sim, planned):
    from node_harness import wait_for
    from wafer_planner_ros.service.cdr import joint_trajectory
    node, watcher = sim
    # Malformed: bytes that are no JointTrajectory, another robot's joints, times that
    # do not ascend. Each is logged and ignored; the arm keeps holding its start.
    watcher.trajectory_pub.publish(b'\x00\x01\x00\x00\xff\xff\xff\x7f')
    rows = planned.positions[:3], planned.velocities[:3], planned.accelerations[:3]
    watcher.trajectory_pub.publish(joint_trajectory(
        0, 0, 'other', ('a', 'b', 'c'), planned.times[:3], *rows))
    watcher.trajectory_pub.publish(joint_trajectory(
        0, 0, 'backwards', NAMES, planned.times[:3][::-1], *rows))
    wait_for(lambda: node.refused == 3, 10.0)
    assert node.followed == 0
    # The plan, to start 0.3 s from now (its header stamp).
    start = time.time() + 0.3
    sec, nanosec = int(start), int(round((start - int(start)) * 1e9))
    seen = len(watcher.joints)
    watcher.trajectory_pub.publish(joint_trajectory(
        sec, nanosec, 'plan-1', NAMES, planned.times, planned.positions, planned.velocities,
        planned.accelerations))
    wait_for(lambda: watcher.joints and _seconds(watcher.joints[-1].header.stamp) >
             start + 1.0, 10.0)
    assert node.followed == 1 and node.refused == 3
    executed = [m for m in watcher.joints[seen:]
                if _seconds(m.header.stamp) <= start + 1.0]
    t = np.array([_seconds(m.header.stamp) for m in executed]) - start
    q = np.array([m.position for m in executed])
    assert len(t) > 40  # 100 Hz, give or take a loaded machine
    waiting = t < 0.0
    assert np.allclose(q[waiting], planned.positions[0], rtol=0.0, atol=1e-12)
    moving = planned.trajectory.evaluate(np.maximum(t[~waiting], 0.0))
    assert np.max(np.abs(q[~waiting] - moving)) < 1e-5  # to the float seconds of a stamp
    assert np.max(np.abs(q[-1] - planned.positions[0])) > 0.05  # it has moved
    ratios = [m.data[3] for m in watcher.wafer[-50:]]
    assert 0.0 < max(ratios) <= 1.0 + 1e-3


def test_wafer_sim_as_a_process_refuses_a_bad_parameter_and_stops_on_sigterm(tmp_path):
    import os
    import signal
    import subprocess
    import sys
    # The domain of this run's worker (``conftest``): what the process hears there is
    # this module's own, and it is asserted on only by its exit.
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
               ROS_LOG_DIR=str(tmp_path / 'log'), PYTHONUNBUFFERED='1')
    env.setdefault('ROS_DOMAIN_ID', str(10 + os.getpid() % 80))
    command = [sys.executable, '-m', 'wafer_planner_ros.node.sim', '--ros-args']
    bad = subprocess.run(command + ['-p', 'initial_station:=nowhere'], env=env,
                         capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2
    assert "no station 'nowhere'" in bad.stdout
    process = subprocess.Popen(command, env=env, stdout=subprocess.PIPE,
                               stderr=subprocess.STDOUT, text=True)
    try:
        for line in process.stdout:  # until it says it runs (or ends)
            if 'simulated arm on' in line:
                break
        process.send_signal(signal.SIGTERM)
        rest = process.communicate(timeout=10)[0]
        assert process.returncode == 0, rest
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
