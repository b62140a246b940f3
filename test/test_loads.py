"""Loaded and empty: each move is planned and verified against the limit set it names."""

import copy

from independent import check
import numpy as np
import pytest
from wafer_planner_ros.cell.model import Cell
from wafer_planner_ros.errors import ErrorCode, PlanningError
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
