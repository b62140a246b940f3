"""
A controlled stop: from any moment of a move to rest on its own path, within every limit.

The checks here share nothing with the stop's own: the stop's states are compared with the
move's at the times its timing maps to, its wafer acceleration is taken from second
differences of wafer-centre positions and its jerk from differences of its acceleration.
"""

import dataclasses

import numpy as np
import pytest
from wafer_planner_ros.errors import ErrorCode, PlanningError
from wafer_planner_ros.planner import Planner, PlannerSettings
from wafer_planner_ros.planner.stop import Prepared
from wafer_planner_ros.trajectory.curve import Trajectory
from wafer_planner_ros.trajectory.jerk_profile import JerkProfile
from wafer_planner_ros.trajectory.methods import WholeCurve
from wafer_planner_ros.trajectory.retimed import Retimed
from wafer_planner_ros.trajectory.stopping import followed, hold_demand, Stop
from wafer_planner_ros.trajectory.verify import limit_ratios, Verification, verify
from wafer_planner_ros.trajectory.verify import verify_joined

STEP = 1e-4
"""s between the independent checks."""
MOMENTS = 10


@pytest.fixture(scope='module')
def planner(default_cell, default_roadmap):
    return Planner(default_cell, default_roadmap, PlannerSettings(method=WholeCurve))


@pytest.fixture(scope='module')
def moves(planner):
    return {name: planner.plan(*ends) for name, ends in (
        ('station', ('loadport1', 'loadlock2')),
        ('port', ('loadport1:inside', 'loadlock2:inside')))}


def _independent(cell, stop, move) -> dict:
    """Return the stop's limit ratios measured without its own code; assert its path."""
    robot = cell.robot
    limits = robot.limit_set
    t = np.linspace(0.0, stop.duration, int(np.ceil(stop.duration / STEP)) + 1)
    q, qd, qdd = stop.evaluate_orders(t, range(3))
    # On the move's path: every configuration is one the move passes through.
    sigma = stop.timing.evaluate(t)[:, 0]
    assert np.array_equal(q, move.evaluate(sigma))
    assert np.all(np.diff(sigma) >= 0.0)
    ratios = {'velocity': np.abs(qd) / limits.joints.velocity,
              'acceleration': np.abs(qdd) / limits.joints.acceleration,
              'jerk': np.abs(np.diff(qdd, axis=0) / STEP) / limits.joints.jerk}
    centre = robot.arm.wafer_center(q)
    ratios['wafer'] = np.abs(np.diff(centre, 2, axis=0) / STEP ** 2) / limits.wafer.xy
    return {name: float(values.max()) for name, values in ratios.items()}


@pytest.mark.parametrize('name', ['station', 'port'])
def test_a_stop_at_ten_moments_keeps_every_limit_and_ends_at_rest_on_the_path(
        planner, moves, name):
    move = moves[name].trajectory
    cell = planner.cell
    early = 0
    for at in np.linspace(0.0, move.duration, MOMENTS + 2)[1:-1]:
        stop = planner.stop(move, at, 'r1')
        curve = stop.trajectory
        q, qd, qdd = (x[0] for x in move.evaluate_orders([at], range(3)))
        s_q, s_qd, s_qdd = (x[0] for x in curve.evaluate_orders([0.0], range(3)))
        # It starts exactly in the move's state there.
        assert np.array_equal(s_q, q)
        assert np.abs(s_qd - qd).max() <= 1e-9 and np.abs(s_qdd - qdd).max() <= 1e-9
        end = curve.evaluate_orders([curve.duration], range(3))
        assert np.abs(np.concatenate([end[1][0], end[2][0]])).max() == 0.0
        assert stop.verification.ok and stop.verification.proof.certified
        for limit, ratio in _independent(cell, curve, move).items():
            assert ratio <= 1.0 + 1e-6, f'{limit} at {ratio} x its limit, stop at {at}'
        # The answer's samples: the stop's, from its first state.
        assert np.array_equal(stop.positions[0], q)
        # Never later at rest than the move itself; early in a station move, far from
        # braking to its goal, braked on the path and sooner. (Through a port, some
        # moments still stop by the rest of the move: safe, not yet sooner.)
        assert curve.duration <= move.duration - at
        if at < 0.3 * move.duration and name == 'station':
            early += 1
            assert stop.metrics['timing'] == 'braked', f'the stop at {at}'
            assert curve.duration < move.duration - at - 0.1, f'the stop at {at}'
    assert early >= 2 or name != 'station'


def test_an_abrupt_hold_demands_more_of_the_wafer_than_the_stop(planner, moves):
    move = moves['station'].trajectory
    at = 0.5 * move.duration
    stop = planner.stop(move, at, 'r1')
    limit = planner.cell.robot.limit_set.wafer.xy.max()
    assert stop.verification.ratios['wafer_x'] <= 1.0
    assert hold_demand(move, at, planner.cell.robot) > 2.0 * limit


def test_a_stop_of_a_stop_works_and_is_described_again(planner, moves):
    move = moves['station'].trajectory
    first = planner.stop(move, 0.2 * move.duration, 'r1').trajectory
    at = 0.3 * first.duration
    second = planner.stop(first, at, 's1')
    assert second.verification.ok
    state = [x[0] for x in first.evaluate_orders([at], range(3))]
    assert np.array_equal(second.positions[0], state[0])
    assert np.abs(second.velocities[0] - state[1]).max() <= 1e-9
    assert second.cycle_time <= first.duration - at
    again = Trajectory.from_description(second.trajectory.describe())
    t = np.linspace(0.0, second.cycle_time, 101)
    assert np.array_equal(again.evaluate(t), second.trajectory.evaluate(t))


@pytest.mark.parametrize('at, code', [(-0.1, ErrorCode.OUTSIDE_TRAJECTORY),
                                      (float('nan'), ErrorCode.OUTSIDE_TRAJECTORY),
                                      ('1.0', ErrorCode.OUTSIDE_TRAJECTORY),
                                      (99.0, ErrorCode.OUTSIDE_TRAJECTORY),
                                      (0.0, ErrorCode.AT_REST), ('end', ErrorCode.AT_REST)])
def test_a_stop_outside_the_move_or_where_it_rests_is_refused_by_name(
        planner, moves, at, code):
    move = moves['station'].trajectory
    with pytest.raises(PlanningError) as raised:
        planner.stop(move, move.duration if at == 'end' else at, 'r1')
    assert raised.value.code is code


def test_a_stop_verified_as_starting_at_rest_or_in_another_motion_fails(planner, moves):
    move = moves['station'].trajectory
    stop = planner.stop(move, 0.5 * move.duration, 'r1')
    curve, q, end = stop.trajectory, stop.start_q, stop.goal_q
    assert not verify(curve, planner.cell, q, end).ok  # it does not start at rest
    qd, qdd = (x[0] for x in move.evaluate_orders([0.5 * move.duration], (1, 2)))
    assert not verify(curve, planner.cell, q, end, moving=(qd * 1.001, qdd)).ok
    assert verify(curve, planner.cell, q, end, moving=(qd, qdd)).ok


def test_a_stop_of_a_verified_move_is_verified_on_its_path_and_in_its_own_limits(
        planner, moves):
    # Given the move's verification, the stop takes its path's proof from it and checks
    # its own limits and ends: a timing that breaks a limit still fails.
    result = moves['station']
    move, at = result.trajectory, 0.4 * result.trajectory.duration
    stop = planner.stop(move, at, 'r1', verified=result.verification)
    whole = planner.stop(move, at, 'r1')
    assert stop.verification.ok and stop.verification.on_base
    assert not whole.verification.on_base
    assert stop.verification.proof is result.verification.proof
    assert stop.verification.min_clearance == result.verification.min_clearance
    assert stop.verification.ratios == pytest.approx(whole.verification.ratios)
    curve, cell = stop.trajectory, planner.cell
    qd, qdd = (x[0] for x in move.evaluate_orders([at], (1, 2)))
    timing = curve.timing
    harder = Retimed(move, JerkProfile(timing.starts / 1.2, timing.jerks * 1.2 ** 3,
                                       timing.states * [1.0, 1.2, 1.2 ** 2]))
    checked = verify(harder, cell, stop.start_q, harder.evaluate([harder.duration])[0],
                     moving=(qd * 1.2, qdd * 1.2 ** 2), base=result.verification)
    assert not checked.ok and any('jerk' in p for p in checked.problems)
    # Only a retimed curve follows a path, and only a proven one.
    with pytest.raises(ValueError):
        verify(move, cell, result.start_q, result.goal_q, base=result.verification)
    with pytest.raises(ValueError):
        verify(curve, cell, stop.start_q, stop.goal_q, moving=(qd, qdd),
               base=Verification(problems=('not proven',)))


def test_a_stop_made_ahead_follows_the_move_to_its_moment_then_brakes_as_it_does(
        planner, moves):
    result = moves['station']
    move = result.trajectory
    at = 0.3 * move.duration
    made = planner.prepare_stop(move, at + 0.013, result.verification)
    assert made.verification.ok and made.verification.on_base
    stop = planner.stop(move, at, 'r1', verified=result.verification, ahead=made)
    curve = stop.trajectory
    assert stop.verification.ok and stop.metrics['braking_from'] == at + 0.013
    # Checked anew: the 13 ms followed and the join; the stop made ahead when it was made.
    whole = planner.stop(move, at, 'r1', ahead=made)  # no proof to follow: verified whole
    assert made.verification.limit_samples < stop.verification.limit_samples \
        <= made.verification.limit_samples + 15
    assert whole.verification.ok and not whole.verification.on_base
    for name, ratio in whole.verification.ratios.items():
        assert stop.verification.ratios[name] == pytest.approx(ratio, rel=1e-3, abs=1e-9)
    for name in ('joint_path_length', 'wafer_path_length'):
        assert stop.metrics[name] == pytest.approx(whole.metrics[name], rel=1e-4)
    assert planner.stop(move, at, 'r1').metrics['braking_from'] == at
    q, qd, qdd = (x[0] for x in move.evaluate_orders([at], range(3)))
    s_q, s_qd, s_qdd = (x[0] for x in curve.evaluate_orders([0.0], range(3)))
    assert np.array_equal(s_q, q)
    assert np.abs(s_qd - qd).max() <= 1e-9 and np.abs(s_qdd - qdd).max() <= 1e-9
    # The move until the moment, then the stop made there.
    t = np.linspace(0.0, 0.013, 14)
    assert np.abs(curve.evaluate(t) - move.evaluate(at + t)).max() <= 1e-12
    braked = made.stop.trajectory
    later = np.linspace(0.0, braked.duration, 50)
    assert np.abs(curve.evaluate(0.013 + later) - braked.evaluate(later)).max() <= 1e-9
    assert curve.duration == pytest.approx(0.013 + braked.duration, abs=1e-12)
    for limit, ratio in _independent(planner.cell, curve, move).items():
        assert ratio <= 1.0 + 1e-6, f'{limit} at {ratio} x its limit'
    # Made from before the moment, or of another curve: refused.
    with pytest.raises(ValueError):
        planner.stop(move, at + 0.02, 'r1', ahead=made)
    with pytest.raises(ValueError):
        planner.stop(moves['port'].trajectory, at, 'r1', ahead=made)


def test_a_joined_verification_checks_the_stretch_followed_and_the_join(planner, moves):
    result = moves['station']
    move, cell, at = result.trajectory, planner.cell, 0.3 * result.trajectory.duration
    made = planner.prepare_stop(move, at + 0.013, result.verification)
    curve = followed(made.stop, move, at).trajectory
    q, qd, qdd = (x[0] for x in move.evaluate_orders([at], range(3)))
    end = curve.evaluate([curve.duration])[0]
    then = (made.stop.trajectory, made.verification)
    assert verify_joined(curve, cell, q, end, (qd, qdd), result.verification, 0.013, then).ok
    # Joined to another stop than the one it goes on as: refused.
    other = planner.prepare_stop(move, at + 0.02, result.verification)
    checked = verify_joined(curve, cell, q, end, (qd, qdd), result.verification, 0.013,
                            (other.stop.trajectory, other.verification))
    assert any('verified stop it joins' in p for p in checked.problems)
    # Another start motion than the move's: refused as ``verify`` refuses it.
    checked = verify_joined(curve, cell, q, end, (qd * 1.01, qdd), result.verification,
                            0.013, then)
    assert any('the motion it continues' in p for p in checked.problems)
    # The stretch's limits are what is checked anew: with the stop's figures blanked, the
    # figures are the move's over those 13 ms.
    blank = dataclasses.replace(made.verification, peak_jerk=(0.0,) * len(qd),
                                ratios=dict.fromkeys(made.verification.ratios, 0.0))
    checked = verify_joined(curve, cell, q, end, (qd, qdd), result.verification, 0.013,
                            (made.stop.trajectory, blank))
    stretch = Retimed(move, JerkProfile(np.array([0.0, 0.013]), np.zeros(1),
                                        np.array([[at, 1.0, 0.0], [at + 0.013, 1.0, 0.0]])))
    assert checked.ok and checked.ratios == limit_ratios(stretch, cell.robot)
    assert max(checked.ratios.values()) > 0.0
    with pytest.raises(ValueError):  # a stop made ahead that is not verified
        verify_joined(curve, cell, q, end, (qd, qdd), result.verification, 0.013,
                      (made.stop.trajectory, Verification(problems=('no',))))
    # A timing that goes on otherwise after the join (one phase's jerk changed): refused,
    # though it joins and ends as the stop made ahead does.
    jerks = curve.timing.jerks.copy()
    jerks[len(jerks) // 2] *= 1.0 + 1e-9
    other = Retimed(move, JerkProfile(curve.timing.starts, jerks, curve.timing.states))
    checked = verify_joined(other, cell, q, end, (qd, qdd), result.verification, 0.013, then)
    assert not checked.ok and 'ill-formed' in checked.problems[0]


def test_a_stop_made_ahead_that_is_the_rest_of_the_move_answers_as_the_rest_joined(
        planner, moves):
    # Late in a time-optimal move the stop is its rest: the answer is the rest of the move
    # from ``at``, checked only over the 13 ms followed and at the join.
    result = moves['station']
    move, at = result.trajectory, 0.85 * result.trajectory.duration
    made = planner.prepare_stop(move, at + 0.013, result.verification)
    assert made.stop.timing == 'rest'
    stop = planner.stop(move, at, 'r1', verified=result.verification, ahead=made)
    assert stop.verification.ok and stop.metrics['braking_from'] == at + 0.013
    assert stop.metrics['timing'] == 'rest' and not stop.metrics['refused']
    assert stop.cycle_time == pytest.approx(move.duration - at, abs=1e-12)
    assert stop.verification.limit_samples <= made.verification.limit_samples + 15
    t = np.linspace(0.0, stop.cycle_time, 40)
    assert np.abs(stop.trajectory.evaluate(t) - move.evaluate(at + t)).max() <= 1e-12


def test_a_stop_made_ahead_that_fails_its_verification_is_not_the_answer(planner, moves):
    # Its timing 1.2 x as fast: the move at the moment does not join it (sigma' 1 against
    # 1.2). The answer is the stop found for the moment itself, and says so.
    result = moves['station']
    move, at = result.trajectory, 0.3 * result.trajectory.duration
    made = planner.prepare_stop(move, at + 0.013, result.verification)
    timing = made.stop.trajectory.timing
    faster = Prepared(Stop(Retimed(move, JerkProfile(
        timing.starts / 1.2, timing.jerks * 1.2 ** 3, timing.states * [1.0, 1.2, 1.2 ** 2])),
        made.stop.share, made.stop.timing), made.verification, made.lengths)
    stop = planner.stop(move, at, 'r1', verified=result.verification, ahead=faster)
    found = planner.stop(move, at, 'r1', verified=result.verification)
    assert stop.verification.ok and stop.metrics['braking_from'] == at
    assert stop.cycle_time == found.cycle_time and not found.metrics['refused']
    assert len(stop.metrics['refused']) == 1 and 'ill-formed' in stop.metrics['refused'][0]


@pytest.mark.parametrize('pair, fraction', [(('loadport3', 'loadlock1'), 6 / 40),
                                            (('loadlock2', 'loadport1'), 12 / 40)])
def test_a_stop_that_follows_the_move_first_starts_exactly_in_its_state(planner, pair,
                                                                        fraction):
    # At these moments no braking at once keeps the limits: the stop follows the move a
    # little first (its start computed from the moment itself, not back from the braking).
    move = planner.plan(*pair).trajectory
    at = fraction * move.duration
    stop = planner.stop(move, at, 'r1')
    assert stop.verification.ok and stop.metrics['timing'] == 'braked'
    assert stop.trajectory.timing.jerks[0] == 0.0  # following the move
    assert np.array_equal(stop.positions[0], move.evaluate([at])[0])


@pytest.mark.parametrize('fraction', [0.2, 0.5, 0.8])
def test_a_divert_starts_in_the_moving_state_and_ends_exactly_at_the_new_goal(
        planner, fraction):
    """
    The divert as one verified curve from the moving state (at 0.2 it once missed its goal).

    The stop then the move from rest, or one curve from the moving state where that is
    found in time and faster (``test_divert``).
    """
    move = planner.plan('loadlock1', 'loadport3').trajectory
    at = fraction * move.duration
    diverted = planner.divert(move, at, 'loadport1')
    curve = diverted.trajectory
    q, qd, qdd = (values[0] for values in move.evaluate_orders([at]))
    (q0, q1), (v0, v1), (a0, a1) = curve.evaluate_orders([0.0, curve.duration])
    assert np.array_equal(q0, q)
    assert np.abs(np.concatenate([v0 - qd, a0 - qdd])).max() <= 1e-9
    assert diverted.goal.label == 'loadport1'
    assert np.array_equal(q1, diverted.goal_q)
    assert np.abs(np.concatenate([v1, a1])).max() <= 1e-9
    assert verify(curve, planner.cell, q, diverted.goal_q, moving=(qd, qdd)).ok
    metrics = diverted.metrics
    if metrics['divert'] == 'stop-then-move':
        assert curve.duration == pytest.approx(metrics['stop_time'] + metrics['onward_time'])
    else:  # one curve from the moving state (test_divert), faster
        assert curve.duration < metrics['stop_then_move_time']
