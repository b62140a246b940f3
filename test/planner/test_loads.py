"""Loaded and empty: each move is planned and verified against the limit set it names."""

import copy

from independent import check
import numpy as np
import pytest
from wafer_planner_ros.cell.model import Cell
from wafer_planner_ros.errors import CellError, ErrorCode, PlanningError
from wafer_planner_ros.planner import Planner, PlannerSettings
from wafer_planner_ros.report import plan_json, roadmap_json
from wafer_planner_ros.roadmap.cache import load_or_build
from wafer_planner_ros.trajectory.methods import WholeCurve
import yaml

PAIR = ('loadport1', 'loadlock2')


def _wafer_ratio(robot, result) -> float:
    """Return the largest wafer acceleration of a result over the loaded wafer limit."""
    t = np.linspace(0.0, result.cycle_time, 4001)
    q, qd, qdd = result.trajectory.evaluate_orders(t, range(3))
    wafer = robot.arm.wafer_acceleration(q, qd, qdd)
    return float(np.max(np.abs(wafer) / robot.limit_sets['loaded'].wafer.xy))


def test_an_empty_move_drops_the_wafer_limit_and_keeps_the_joint_limits(
        cell, roadmap_cache):
    cached = load_or_build(cell, cache_dir=roadmap_cache)
    planner = Planner(cell, cached.roadmap, PlannerSettings(method=WholeCurve))
    loadport, loadlock = (next(n for n in sorted(cell.stations) if n.startswith(kind))
                          for kind in ('loadport', 'loadlock'))
    loaded = planner.plan(loadport, loadlock)
    empty = planner.plan(loadport, loadlock, load='empty')
    assert (loaded.load, empty.load) == ('loaded', 'empty')
    info = roadmap_json(cached)
    for result in (loaded, empty):
        plan = plan_json(result, info, cell.robot.joint_names)
        assert plan['load'] == result.load
        ratios = check(cell, plan, result.start_q, result.goal_q)
        assert ('wafer' in ratios) == (result.load == 'loaded')
    assert set(empty.verification.ratios) == {'velocity', 'acceleration', 'jerk'}
    # Without the wafer limit the blade may accelerate harder than a wafer would stay on
    # it, and the move is faster for it.
    assert _wafer_ratio(cell.robot, loaded) <= 1.0 < _wafer_ratio(cell.robot, empty)
    assert empty.cycle_time < loaded.cycle_time


def test_raised_empty_joint_limits_are_used_for_empty_moves_only(
        default_cell_file, default_roadmap, roadmap_cache):
    with open(default_cell_file) as f:
        document = yaml.safe_load(f)
    raised = copy.deepcopy(document)
    limits = raised['robot']['joint_limits']
    raised['robot']['empty_joint_limits'] = {
        key: [2.0 * v for v in limits[key]] for key in ('velocity', 'acceleration', 'jerk')}
    cell = Cell.from_dict(raised)
    plain = Cell.from_dict(document)
    assert cell.digest != plain.digest  # a table or a recording tells them apart
    empty = cell.robot.limit_sets['empty'].joints
    assert empty.velocity.tolist() == [8.4, 16.8, 12.6]
    assert cell.robot.limits.velocity.tolist() == limits['velocity']  # loaded: as before
    roadmap = default_roadmap
    fast = Planner(cell, roadmap).plan(*PAIR, load='empty')
    slow = Planner(plain, roadmap).plan(*PAIR, load='empty')
    loaded = Planner(cell, roadmap).plan(*PAIR)
    assert fast.verification.ok and fast.cycle_time < slow.cycle_time
    # The empty move uses the raised limits: beyond the loaded ones, within its own.
    t = np.linspace(0.0, fast.cycle_time, 4001)
    qdd = fast.trajectory.evaluate_orders(t, range(3))[2]
    assert np.max(np.abs(qdd) / cell.robot.limits.acceleration) > 1.0
    assert np.max(np.abs(qdd) / empty.acceleration) <= 1.0
    assert loaded.cycle_time == pytest.approx(Planner(plain, roadmap).plan(*PAIR).cycle_time)


def test_an_unknown_load_is_an_invalid_request(default_cell, default_roadmap):
    with pytest.raises(PlanningError) as caught:
        Planner(default_cell, default_roadmap).plan(*PAIR, load='half')
    assert caught.value.code == ErrorCode.INVALID_REQUEST
    assert "unknown load 'half'" in caught.value.message


def test_an_empty_move_keeps_the_end_effectors_envelope_clear_not_the_wafers(
        default_cell_file, default_roadmap):
    with open(default_cell_file) as f:
        document = yaml.safe_load(f)
    document['robot']['empty_envelope_radius'] = 0.05
    cell = Cell.from_dict(document)
    empty = cell.with_load('empty')
    assert (cell.robot.end_radius, empty.robot.end_radius) == (0.15, 0.05)
    # Loaded moves keep the wafer's clearance, empty ones the envelope's: 0.10 m more room
    # for the last body wherever the wafer is the closest to a wall.
    q = np.array([c.q for s in cell.stations.values() for c in s.configs])
    loaded_clearance = cell.clearance_model.body_clearance(q)[:, 3]
    empty_clearance = empty.clearance_model.body_clearance(q)[:, 3]
    assert np.allclose(empty_clearance, loaded_clearance + 0.10)
    result = Planner(cell, default_roadmap).plan(*PAIR, load='empty')
    plan = plan_json(result, roadmap_json(load_or_build(cell)), cell.robot.joint_names)
    check(cell, plan, result.start_q, result.goal_q)
    assert result.verification.ok


@pytest.mark.parametrize('radius, says', [
    (0.2, 'must not exceed the wafer radius (0.15 m)'), (0.0, 'must be > 0'),
    ('big', 'must be a number')])
def test_an_envelope_larger_than_the_wafer_or_not_a_radius_is_refused(
        default_cell_file, radius, says):
    with open(default_cell_file) as f:
        document = yaml.safe_load(f)
    document['robot']['empty_envelope_radius'] = radius
    with pytest.raises(CellError) as caught:
        Cell.from_dict(document)
    assert caught.value.path == 'robot.empty_envelope_radius'
    assert says in str(caught.value)
