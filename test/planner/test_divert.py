"""A move diverted in motion: one curve from the moving state where one is found, else a stop."""

import time

from independent import check
import numpy as np
import pytest
from wafer_planner_ros.planner import Planner, PlannerSettings
from wafer_planner_ros.planner import stop as stop_module
from wafer_planner_ros.report import plan_json
from wafer_planner_ros.trajectory.chained import Chained
from wafer_planner_ros.trajectory.continuing import Continuing
from wafer_planner_ros.trajectory.methods import WholeCurve


@pytest.fixture(scope='module')
def planner(default_cell, default_roadmap):
    return Planner(default_cell, default_roadmap, PlannerSettings(method=WholeCurve))


@pytest.fixture(scope='module')
def move(planner):
    return planner.plan('loadlock1', 'loadport1').trajectory


def test_a_divert_is_one_curve_from_the_moving_state_where_one_is_found(
        planner, move, monkeypatch):
    # Not bounded by the clock here (the node's divert has BLEND_SECONDS): the same curve
    # on any machine.
    monkeypatch.setattr(stop_module, 'BLEND_SECONDS', 60.0)
    at = 0.6 * move.duration
    diverted = planner.divert(move, at, 'loadport2')
    curve = diverted.trajectory
    assert diverted.metrics['divert'] == 'blended-divert' and type(curve) is Continuing
    q, qd, qdd = (x[0] for x in move.evaluate_orders([at], range(3)))
    (q0, q1), (v0, v1), (a0, a1) = curve.evaluate_orders([0.0, curve.duration], range(3))
    # It continues the move exactly (no jump in position, velocity or acceleration) and
    # comes to rest exactly at the new goal.
    assert np.array_equal(q0, q)
    assert np.abs(v0 - qd).max() <= 1e-9 and np.abs(a0 - qdd).max() <= 1e-9
    assert np.array_equal(q1, diverted.goal_q) and diverted.goal.label == 'loadport2'
    assert np.abs(np.concatenate([v1, a1])).max() <= 1e-9
    assert diverted.verification.ok and diverted.verification.proof.certified
    # Evaluated by scipy from its knots and control points as exported: every limit, the
    # ports, no collision (``independent.check``).
    check(planner.cell, plan_json(diverted, {}, planner.cell.robot.joint_names), q,
          diverted.goal_q, moving=(qd, qdd))
    # Faster than stopping first: the robot never stands still on the way.
    assert curve.duration < 0.9 * diverted.metrics['stop_then_move_time']
    assert diverted.cycle_time == curve.duration


@pytest.mark.parametrize('why', ['no time', 'the robot is there'])
def test_a_divert_without_time_for_one_curve_stops_then_moves(planner, move, monkeypatch, why):
    monkeypatch.setattr(stop_module, 'BLEND_SECONDS', 0.0 if why == 'no time' else 60.0)
    # The robot passes the moment now: an answer found later would come too late.
    leaves = time.monotonic() if why == 'the robot is there' else None
    drafted = []
    monkeypatch.setattr(stop_module, 'draft', lambda *a: drafted.append(a) or None)
    diverted = planner.divert(move, 0.6 * move.duration, 'loadport2', leaves=leaves)
    assert not drafted  # not sought at all
    assert diverted.metrics['divert'] == 'stop-then-move'
    assert isinstance(diverted.trajectory, Chained) and diverted.verification.ok
    assert diverted.cycle_time == pytest.approx(diverted.metrics['stop_time']
                                                + diverted.metrics['onward_time'])


def test_a_divert_in_one_curve_stops_on_its_own_path(planner, move, monkeypatch):
    monkeypatch.setattr(stop_module, 'BLEND_SECONDS', 60.0)
    diverted = planner.divert(move, 0.6 * move.duration, 'loadport2')
    assert diverted.metrics['divert'] == 'blended-divert'
    curve = diverted.trajectory
    at = 0.3 * curve.duration
    stopped = planner.stop(curve, at, 'd1', verified=diverted.verification)
    assert stopped.verification.ok and stopped.verification.on_base
    stop = stopped.trajectory
    assert stop.base is curve
    (q0, v0, a0), end = ([x[0] for x in stop.evaluate_orders([0.0], range(3))],
                         stop.evaluate_orders([stop.duration], range(3)))
    q, qd, qdd = (x[0] for x in curve.evaluate_orders([at], range(3)))
    assert np.array_equal(q0, q)
    assert np.abs(v0 - qd).max() <= 1e-9 and np.abs(a0 - qdd).max() <= 1e-9
    assert np.abs(np.concatenate([end[1][0], end[2][0]])).max() == 0.0
