"""The library of optima: answers kept by their ends, drafts for requests near them."""

from dataclasses import replace
import json
from pathlib import Path

from independent import check
import numpy as np
import pytest

from wafer_planner_ros.planner import Planner
from wafer_planner_ros.planner.optima import Optima, OPTIMA_KEPT, REACH
from wafer_planner_ros.report import plan_json
from wafer_planner_ros.service.optima_store import load_optima, optima_path, OptimaError
from wafer_planner_ros.service.optima_store import save_optima
from wafer_planner_ros.service.table import table_key
from wafer_planner_ros.service.table_store import content_digest
from wafer_planner_ros.trajectory.bspline import CubicBSpline
from wafer_planner_ros.trajectory.methods import WholeCurve
from wafer_planner_ros.trajectory.tuning import TimingSettings
from wafer_planner_ros.trajectory.verify import limit_ratios, verify
from wafer_planner_ros.trajectory.warm import moved_to

START = np.array([-1.2, 2.4, 1.3])
GOAL = np.array([1.0, -2.0, -1.0])
NEAR = np.array([0.04, -0.03, 0.05])
"""rad: how far the near request's ends are from the optimum's (inside ``REACH``)."""


def _checked(cell, roadmap, answer) -> None:
    """Assert what the independent dense check asserts of an answer."""
    check(cell, plan_json(answer, {'hash': roadmap.digest}, cell.robot.joint_names),
          answer.start_q, answer.goal_q)


def _line(a, b, seconds: float) -> CubicBSpline:
    points = np.linspace(a, b, 8)
    points[:3], points[-3:] = a, b
    return CubicBSpline.from_intervals(points, np.full(5, seconds / 5))


@pytest.fixture(scope='module')
def planner(default_cell, default_roadmap):
    """Return a whole-curve planner of its own: its library starts empty."""
    return Planner(default_cell, default_roadmap).with_method(WholeCurve)


@pytest.fixture(scope='module')
def optimum(planner):
    """Return the unbudgeted answer from START to GOAL (kept in the planner's library)."""
    return planner.plan(START, GOAL)


def test_the_library_keeps_the_fastest_curve_of_each_pair_of_ends_and_the_newest():
    a, b, c = np.zeros(3), np.ones(3), np.full(3, 2.0)
    optima = Optima(size=2)
    assert optima.add(a, b, _line(a, b, 2.0))
    assert not optima.add(a, b, _line(a, b, 3.0))  # slower for the same ends
    assert optima.add(a, b, _line(a, b, 1.5)) and len(optima) == 1
    assert optima.nearest(a, b).duration == 1.5
    serial = optima.serial
    optima.add(b, c, _line(b, c, 1.0))
    optima.add(a, c, _line(a, c, 1.0))  # the oldest (a -> b) goes
    assert len(optima) == 2 and [o.serial > serial for o in optima.since(serial)] == [1, 1]
    assert optima.nearest(a + 0.01, b) is None  # a -> b is gone; nothing else near


def test_a_request_near_an_optimum_is_drafted_from_it_forwards_or_backwards():
    a, b = np.zeros(3), np.ones(3)
    optima = Optima()
    optima.add(a, b, _line(a, b, 2.0))
    assert optima.nearest(a + 0.9 * REACH, b - 0.9 * REACH).control_points[0] == \
        pytest.approx(a)
    backwards = optima.nearest(b, a + 0.1)
    assert backwards.control_points[0] == pytest.approx(b)  # run backwards: from b
    assert optima.nearest(a + 1.1 * REACH, b) is None  # too far at the start


def test_a_moved_optimum_starts_and_ends_at_rest_on_the_new_ends_within_every_limit(
        default_cell, optimum):
    curve = optimum.trajectory
    a, b = curve.control_points[0] + NEAR, curve.control_points[-1] - NEAR
    moved = moved_to(curve, a, b, default_cell.robot, TimingSettings())
    q, qd, qdd = moved.evaluate_orders(np.array([0.0, moved.duration]), (0, 1, 2))
    assert np.array_equal(q, np.stack([a, b]))
    assert not qd.any() and not qdd.any()
    assert max(limit_ratios(moved, default_cell.robot).values()) <= 1.0 + 1e-9
    same = moved_to(curve, curve.control_points[0], curve.control_points[-1],
                    default_cell.robot, TimingSettings())
    assert np.allclose(same.control_points, curve.control_points, atol=1e-12)


def test_an_optimum_with_short_end_spans_moves_without_slowing_down(default_cell):
    # An optimum of the default cell from START to GOAL (test/support/curves), whose
    # first and last spans last 8-13 ms against tenths of a second between: moved by the
    # points' time along it, the short spans move with their neighbours and the draft is
    # 1.13 times the optimum's cycle time; moved by the points' order, those spans' jerk
    # was 15 times the limit before λ-scaling, and the draft 2.48 times.
    curve = CubicBSpline.described(json.loads(
        (Path(__file__).parents[1] / 'support' / 'curves' / 'short_end_spans.json').read_text()))
    robot = default_cell.robot
    moved = moved_to(curve, START + NEAR, GOAL - NEAR, robot, TimingSettings())
    assert max(limit_ratios(moved, robot).values()) <= 1.0 + 1e-9
    assert moved.duration <= 1.2 * curve.duration


def test_a_budgeted_request_near_an_optimum_starts_from_it_and_is_verified(
        planner, optimum, default_cell):
    a, b = START + NEAR, GOAL - NEAR
    answer = planner.plan(a, b, budget=0.12)
    assert answer.metrics.get('from_optimum') is True
    assert verify(answer.trajectory, default_cell, a, b).ok
    _checked(default_cell, planner.roadmap, answer)  # the independent dense check
    # Its draft was the optimum moved: the answer runs between the request's ends, not the
    # kept curve's, and is as fast as the optimum to within the ends' move.
    assert np.array_equal(answer.positions[0], a) and np.array_equal(answer.positions[-1], b)
    assert answer.cycle_time == pytest.approx(optimum.cycle_time, rel=0.05)
    # Without a budget the library is not used: the same answer as from an empty one.
    fresh = Planner(planner.cell, planner.roadmap).with_method(WholeCurve)
    assert planner.plan(a, b).cycle_time == fresh.plan(a, b).cycle_time


def test_a_draft_through_a_wall_is_never_the_answer(planner, default_cell):
    # A kept curve edited to pass through the cell's walls (a control point far out):
    # the request near it is still answered by a proven, verified curve.
    edited = Optima()
    line = _line(START, GOAL, 3.0)
    points = line.control_points.copy()
    points[4] += np.array([2.5, -2.5, 2.5])
    edited.add(START, GOAL, CubicBSpline(line.knots, points))
    assert not verify(CubicBSpline(line.knots, points), default_cell, START, GOAL).ok
    other = Planner(planner.cell, planner.roadmap).with_method(WholeCurve)
    other._optima[other.load] = edited
    answer = other.plan(START + NEAR, GOAL - NEAR, budget=0.12)
    assert verify(answer.trajectory, default_cell, START + NEAR, GOAL - NEAR).ok
    _checked(default_cell, planner.roadmap, answer)


def test_the_library_is_stored_and_every_optimum_verified_on_load(planner, optimum, tmp_path):
    path = save_optima(planner, tmp_path)
    assert path == optima_path(tmp_path, table_key(planner))
    again = Planner(planner.cell, planner.roadmap).with_method(WholeCurve)
    loaded = load_optima(again, tmp_path)
    assert loaded.kept == len(planner.optima) >= 1 and loaded.rejected == ()
    assert again.optima.nearest(START, GOAL).duration == optimum.cycle_time


def test_an_edited_library_file_changes_nothing_but_speed(planner, optimum, tmp_path,
                                                          default_cell):
    planner.plan('loadport1', 'loadlock2')  # a second optimum, kept
    for kept in planner.optima.entries():  # more optima: the same moves backwards
        planner.optima.add(kept.goal, kept.start, kept.curve.backwards())
    assert len(planner.optima) >= 4
    path = save_optima(planner, tmp_path)
    document = json.loads(path.read_text())
    count = len(document['optima'])
    # Edited on purpose, its digest made to match: one optimum's curve through a wall,
    # another's ends moved off its curve, a third's knots halved (beyond the limits).
    document['optima'][0]['trajectory']['control_points'][4] = [3.0, -3.0, 3.0]
    document['optima'][1]['start'] = [0.0, 0.0, 0.0]
    document['optima'][-1]['trajectory']['knots'] = [
        0.5 * t for t in document['optima'][-1]['trajectory']['knots']]
    document['digest'] = content_digest([document['optima']])
    path.write_text(json.dumps(document))
    again = Planner(planner.cell, planner.roadmap).with_method(WholeCurve)
    loaded = load_optima(again, tmp_path)
    assert loaded.kept == count - 3 and len(loaded.rejected) == 3
    assert [reason.split(':')[0] for reason in loaded.rejected] == [
        'optimum 0', 'optimum 1', f'optimum {count - 1}']
    for kept in again.optima.entries():
        assert verify(kept.curve, default_cell, kept.start, kept.goal).ok
    # A request near the optimum whose file entry was edited is still answered, verified.
    answer = again.plan(START + NEAR, GOAL - NEAR, budget=0.12)
    _checked(default_cell, planner.roadmap, answer)
    # Damage (the digest no longer matches), too many optima or another key: the file is
    # passed over whole.
    path.write_text(path.read_text().replace('"format": 1', '"format": 1 ', 1)[:-40])
    with pytest.raises(OptimaError, match='unreadable'):
        load_optima(again, tmp_path)
    document['optima'][2]['goal'][0] += 1e-3
    path.write_text(json.dumps(document))
    with pytest.raises(OptimaError, match='does not match its digest'):
        load_optima(again, tmp_path)
    many = dict(document, optima=document['optima'] * (OPTIMA_KEPT // count + 1))
    many['digest'] = content_digest([many['optima']])
    path.write_text(json.dumps(many))
    with pytest.raises(OptimaError, match='more than a planner keeps'):
        load_optima(again, tmp_path)
    document['key'] = '0' * 64
    document['digest'] = content_digest([document['optima']])
    path.write_text(json.dumps(document))
    with pytest.raises(OptimaError, match='another cell'):
        load_optima(again, tmp_path)


def test_a_retaught_stations_requests_start_from_its_old_optima(default_cell, default_roadmap,
                                                                tmp_path):
    from wafer_planner_ros.cell.model import Cell, default_cell_path
    first = Planner(default_cell, default_roadmap).with_method(WholeCurve)
    before = first.plan('loadport2', 'loadlock1')
    save_optima(first, tmp_path)
    # loadport2 re-taught 5 mm away: another cell, so another key; the same basis.
    text = default_cell_path().read_text().replace(
        'loadport2: {wafer_center: [0.0, 0.26]', 'loadport2: {wafer_center: [0.005, 0.26]')
    (tmp_path / 'cell.yaml').write_text(text)
    moved = Cell.from_yaml(tmp_path / 'cell.yaml')
    second = Planner(moved, default_roadmap).with_method(WholeCurve)
    assert table_key(second) != table_key(first)
    loaded = load_optima(second, tmp_path)
    assert loaded.path == optima_path(tmp_path, table_key(first))
    assert loaded.kept == len(first.optima) and loaded.rejected == ()
    answer = second.plan('loadport2', 'loadlock1', budget=0.12)
    assert answer.metrics.get('from_optimum') is True
    assert verify(answer.trajectory, moved, answer.start_q, answer.goal_q).ok
    assert answer.cycle_time == pytest.approx(before.cycle_time, rel=0.03)
    # Of another robot (a limit changed), no file is read.
    robot = moved.robot
    slower = replace(moved, robot=robot.with_limit_set(replace(robot.limit_set, joints=replace(
        robot.limits, velocity=0.9 * robot.limits.velocity))))
    with pytest.raises(OptimaError, match='no optima file'):
        load_optima(Planner(slower, default_roadmap).with_method(WholeCurve), tmp_path)
