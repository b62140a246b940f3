"""
Stops and diverts executed: the node and the simulated arm, a loaded move changed in motion.

The arm (``wafer-sim``, a process of its own) executes the node's trajectories as
``joint_trajectory_controller`` does; a stop or a divert, stamped where it starts, replaces
the rest of the move there. What the arm did is read back from ``/joint_states`` (100 Hz).
"""

import signal
import subprocess
import sys
import time

from node_harness import values, wait_for
import numpy as np
import pytest

from wafer_planner_ros.planner import Planner
from wafer_planner_ros.planner.stop import Prepared
from wafer_planner_ros.service.prepared_stops import AHEAD, EVERY
from wafer_planner_ros.trajectory.stopping import controlled_stop

START = 'loadport1'
GOAL = 'loadlock2'
LEAD = 0.3
"""s between sending a stop request and the moment it stops at: the answer must come first
(milliseconds from a stop the node made ahead of the running move, which it does up to
0.5 s ahead; tens of ms where it finds one, more under the whole suite)."""
DIVERT_LEAD = 1.0
"""s between sending a divert and the moment it leaves the move at: the divert plans the
move from where the stop rests first."""


@pytest.fixture(scope='module')
def arm_and_node(roadmap_cache, tmp_path_factory):
    """Yield the node, and the simulated arm in a process of its own at ``START``."""
    from node_harness import Harness, isolate_dds
    isolate_dds(tmp_path_factory.mktemp('dds'))
    # Its own process, as ``make run`` starts it: in this one the arm's executor would wait
    # for the GIL behind the node's and the test's, and publish at a few Hz.
    arm = subprocess.Popen([sys.executable, '-m', 'wafer_planner_ros.node.sim', '--ros-args',
                            '-p', f'initial_station:={START}'],
                           stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    running = None
    try:
        running = Harness({'roadmap.cache_dir': str(roadmap_cache), 'planning.timeout': 30.0,
                           'recording.directory': str(tmp_path_factory.mktemp('recordings'))})
        from sensor_msgs.msg import JointState
        running.joint_states = []
        running.peer.create_subscription(JointState, '/joint_states',
                                         running.joint_states.append, 1000)
        wait_for(lambda: running.joint_states, 60.0)
        yield running
    finally:
        arm.send_signal(signal.SIGINT)
        try:
            arm.wait(timeout=10)
        except subprocess.TimeoutExpired:
            arm.kill()
        if running is not None:
            running.close()


def _seconds(stamp) -> float:
    return stamp.sec + 1e-9 * stamp.nanosec


def _back_to_start(harness, cell, tag) -> None:
    """Bring the arm to rest at ``START`` (a case before left it somewhere on its way)."""
    here = np.array(harness.joint_states[-1].position)
    if np.abs(here - cell.stations[START].configs[0].q).max() > 1e-9:
        harness.send_stations({'id': f'back-{tag}', 'from': here.tolist(), 'to': START})
        assert values(harness.result(f'back-{tag}'))['code'] == 'OK'
        wait_for(lambda: not np.any(harness.joint_states[-1].velocity) and np.abs(
            np.array(harness.joint_states[-1].position)
            - cell.stations[START].configs[0].q).max() < 1e-9, 30.0)


def _published(harness, request_id: str):
    """Return the trajectory published for ``request_id`` (waiting for it)."""
    wait_for(lambda: any(t.header.frame_id == request_id for t in harness.trajectories), 10)
    return next(t for t in harness.trajectories if t.header.frame_id == request_id)


def _expected(trajectory, t: np.ndarray) -> tuple:
    """
    Return (q, q') of a published trajectory at times t after its start, from its samples.

    Each from the sample at or before it, by its velocity and acceleration (a Taylor step
    of less than one sample period: off by at most the jerk limit times the step cubed).
    """
    times = np.array([p.time_from_start.sec + 1e-9 * p.time_from_start.nanosec
                      for p in trajectory.points])
    q, qd, qdd = (np.array([getattr(p, name) for p in trajectory.points])
                  for name in ('positions', 'velocities', 'accelerations'))
    k = np.clip(np.searchsorted(times, t, side='right') - 1, 0, len(times) - 1)
    step = np.clip(t - times[k], 0.0, None)[:, None]
    return q[k] + qd[k] * step + 0.5 * qdd[k] * step ** 2, qd[k] + qdd[k] * step


# Ten moments of the move, from the first a stop request can reach in time (``LEAD`` after
# the move's answer) to near its end; the core's test stops it from its start on.
@pytest.mark.parametrize('share', [0.42, 0.47, 0.52, 0.57, 0.63, 0.68, 0.73, 0.79, 0.84, 0.9])
def test_a_moving_arm_stopped_on_its_path_is_continuous_and_within_its_limits(
        arm_and_node, default_cell, default_roadmap, share):
    harness = arm_and_node
    robot = default_cell.robot
    request_id = f'go-{share}'
    _back_to_start(harness, default_cell, share)
    # Planned here before the arm moves: planning in this process while it moves would
    # hold up the arm's executor thread (the GIL), as no separate robot is held up.
    move = Planner(default_cell, default_roadmap).plan(START, GOAL).trajectory
    harness.send_stations({'id': request_id, 'from': START, 'to': GOAL})
    assert values(harness.result(request_id))['code'] == 'OK'
    sent = _published(harness, request_id)
    began = _seconds(sent.header.stamp)
    assert float(values(harness.result(request_id))['cycle_time']) == move.duration
    at = max(share * move.duration, time.time() - began + LEAD)
    wait_for(lambda: time.time() >= began + at - LEAD, 10.0)
    harness.send_stop({'id': f'stop-{share}', 'trajectory': request_id, 'at': at})
    result = harness.result(f'stop-{share}')
    assert values(result)['code'] == 'OK', result.message
    received = time.time()
    assert received < began + at, 'the stop came after the moment it stops at'
    stop_time = float(values(result)['cycle_time'])
    wait_for(lambda: _seconds(harness.joint_states[-1].header.stamp) > began + at + stop_time
             + 0.1, 20.0)
    executed = [m for m in harness.joint_states
                if began - 0.05 <= _seconds(m.header.stamp) <= began + at + stop_time + 0.1]
    t = np.array([_seconds(m.header.stamp) for m in executed]) - began
    q = np.array([m.position for m in executed])
    qd = np.array([m.velocity for m in executed])
    # Continuous across the splice at ``at``: no jump in position or velocity (each step
    # within what the limits allow over the time between two states), the acceleration
    # from the velocities within its limit, and the motion the continuous one of the move
    # until ``at`` and the stop after it (the core's, below): position and velocity within
    # the departure of the controller's quintic between its 10 ms samples from the curve
    # (the jerk limit times a step cubed, squared). (From its own start on: a move the arm
    # receives after its stamp is picked up where it should be by then, as a controller
    # does, which is the node's stamping of moves, not the stop.)
    limits = robot.limit_set.joints
    planner = Planner(default_cell, default_roadmap)
    # The core's stop there: braking from the moment the node's answer says (a stop made
    # ahead follows the move to its moment first, at most EVERY later).
    braking = float(values(result)['braking_from'])
    # At ``at``, or at a moment made ahead: on the grid, within a stride of them (a
    # moment or more where making them takes longer than the node's share of a core).
    assert braking == at or (at < braking < at + AHEAD and
                             abs(braking / EVERY - round(braking / EVERY)) < 1e-9)
    stop = planner.stop(move, at, request_id, ahead=None if braking == at else
                        Prepared(controlled_stop(move, braking, planner.cell.robot), None,
                                 None))
    near = t >= at - 0.1
    dt = np.diff(t[near])[:, None]
    assert np.all(np.abs(np.diff(q[near], axis=0)) <= limits.velocity * dt * (1 + 1e-6) + 1e-9)
    qdd = np.diff(qd[near], axis=0) / dt
    assert np.all(np.abs(qdd) <= limits.acceleration * (1 + 1e-3))
    around = np.abs(t - at) < 0.1
    assert around.sum() >= 3
    later = t[around] >= at
    expected = [np.where(later[:, None], stopped, moving) for stopped, moving in zip(
        stop.trajectory.evaluate_orders(np.maximum(t[around] - at, 0.0), (0, 1)),
        move.evaluate_orders(t[around], (0, 1)))]
    step = 0.01
    assert np.abs(q[around] - expected[0]).max() < limits.jerk.max() * step ** 3
    assert np.abs(qd[around] - expected[1]).max() < limits.jerk.max() * step ** 2
    # Within every limit: velocities, accelerations (from the velocities), the wafer's.
    assert np.all(np.abs(qd) <= limits.velocity * (1 + 1e-9))
    # While it stops, the arm follows the stop the core makes of the same move there, a
    # curve that keeps every limit (checked densely, and independently, in
    # test/trajectory/test_stopping.py), to within the controller's quintic between its
    # 10 ms samples (less than the jerk limit times a step cubed).
    assert stop.verification.ok and max(stop.verification.ratios.values()) <= 1.0
    assert stop.cycle_time == stop_time
    stopping = (t >= at) & (t <= at + stop_time)
    # The arm publishes at 100 Hz, fewer when both cores are busy (28 Hz under the whole
    # suite once): each check here holds whatever the spacing of the states it reads.
    assert stopping.sum() >= 3
    curve = stop.trajectory.evaluate(t[stopping] - at)
    assert np.abs(q[stopping] - curve).max() < limits.jerk.max() * 0.01 ** 3
    # At rest on the move's path: short of the goal when braked, at it when no braking on
    # the path ends sooner than the rest of the move; before ``at``, the move itself.
    goal = move.evaluate([move.duration])[0]
    assert not np.any(qd[-1])
    if stop.metrics['timing'] == 'rest':
        assert np.array_equal(q[-1], goal)
    else:
        assert np.abs(q[-1] - goal).max() > 0.01
    dense = move.evaluate(np.linspace(0.0, move.duration, 40001))
    assert np.abs(dense - q[-1]).max(axis=1).min() < 1e-3
    # The controller's quintic between the samples follows the move exactly (sampled at its
    # breaks too); within the jerk limit times a step cubed, whatever the arm's spacing.
    before = (t > 0.25) & (t < at)  # once the arm follows it (it may come late: above)
    assert np.abs(q[before] - move.evaluate(t[before])).max() < limits.jerk.max() * 0.01 ** 3


def test_a_moving_arm_diverted_follows_the_move_then_the_divert_without_a_jump(
        arm_and_node, default_cell):
    harness = arm_and_node
    limits = default_cell.robot.limit_set.joints
    _back_to_start(harness, default_cell, 'divert')
    harness.send_stations({'id': 'go-divert', 'from': START, 'to': GOAL})
    assert values(harness.result('go-divert'))['code'] == 'OK'
    sent = _published(harness, 'go-divert')
    began = _seconds(sent.header.stamp)
    at = time.time() - began + DIVERT_LEAD
    harness.send_stations({'id': 'divert', 'from': {'trajectory': 'go-divert', 'at': at},
                           'to': 'loadlock1'})
    result = harness.result('divert')
    assert values(result)['code'] == 'OK', result.message
    # One curve from the moving state where the optimiser finds one in time, else the
    # stop then the move: either joins the move without a jump.
    assert values(result)['method'] in ('stop-then-move', 'blended-divert')
    diverted = _published(harness, 'divert')
    assert time.time() < began + at, 'the divert came after the moment it leaves the move at'
    assert _seconds(diverted.header.stamp) == pytest.approx(began + at, abs=1e-6)
    duration = float(values(result)['cycle_time'])
    wait_for(lambda: _seconds(harness.joint_states[-1].header.stamp) > began + at + duration
             + 0.1, 30.0)
    executed = [m for m in harness.joint_states
                if began + at - 0.2 <= _seconds(m.header.stamp) <= began + at + duration + 0.1]
    t = np.array([_seconds(m.header.stamp) for m in executed]) - began
    q = np.array([m.position for m in executed])
    qd = np.array([m.velocity for m in executed])
    assert (np.abs(t - at) < 0.1).sum() >= 3
    # The move until ``at``, the divert from there: position and velocity each within the
    # controller's quintic between the 10 ms samples of the curve (the jerk limit times a
    # step cubed, squared), so nothing jumps where one replaces the other.
    later = t >= at
    moving = _expected(sent, t)
    diverting = _expected(diverted, np.maximum(t - at, 0.0))
    expected_q = np.where(later[:, None], diverting[0], moving[0])
    expected_qd = np.where(later[:, None], diverting[1], moving[1])
    assert np.abs(q - expected_q).max() < limits.jerk.max() * 0.01 ** 3
    assert np.abs(qd - expected_qd).max() < limits.jerk.max() * 0.01 ** 2
    dt = np.diff(t)[:, None]
    assert np.all(np.abs(np.diff(qd, axis=0)) / dt <= limits.acceleration * (1 + 1e-3))
    assert np.all(np.abs(qd) <= limits.velocity * (1 + 1e-9))
    # At rest at the new station.
    assert not np.any(qd[-1])
    assert any(np.abs(q[-1] - config.q).max() < 1e-9
               for config in default_cell.stations['loadlock1'].configs)
