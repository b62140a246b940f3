"""B-spline evaluation and derivatives, the corridor's proof, and the time optimisation."""

from dataclasses import replace
import json

import numpy as np
import pytest
from scipy.interpolate import BSpline

from wafer_planner_ros.roadmap.search import find_path
from wafer_planner_ros.roadmap.shortcut import shortcut
from wafer_planner_ros.trajectory import timing as timing_module
from wafer_planner_ros.trajectory.bspline import CubicBSpline
from wafer_planner_ros.trajectory.constraints import limit_constraints, ratio_orders
from wafer_planner_ros.trajectory.constraints import state_ratios, States
from wafer_planner_ros.trajectory.corridor import build_corridor, simplify
from wafer_planner_ros.trajectory.curve import Trajectory
from wafer_planner_ros.trajectory.timing import optimise
from wafer_planner_ros.trajectory.timing_problem import scaled_start, TimingProblem
from wafer_planner_ros.trajectory.tuning import TimingSettings
from wafer_planner_ros.trajectory.verify import COLLISION_STEP, collision_times
from wafer_planner_ros.trajectory.verify import limit_ratios, verify

MARGIN = TimingSettings().margin
"""The optimiser's tightening of the limits (its default tuning)."""

PEAK_BETWEEN_SAMPLES = (
    np.array([-1.1700711684872604, 2.423652420735181, 1.3388026000994313]),
    np.array([-1.7122484869689896, -2.949758921692892, -2.7240628830999567]))
"""A free joint pair of the default cell whose λ-scaled start (λ = 34; 25 since the cell has
port pockets) exceeded the wafer limit by 0.02 % between the instants its λ was taken from,
34 ms apart once scaled."""


@pytest.fixture()
def spline():
    """Return a random clamped spline with triple end points."""
    rng = np.random.default_rng(71)
    points = rng.normal(size=(10, 3))
    points[1:3], points[-3:-1] = points[0], points[-1]
    return CubicBSpline.from_intervals(points, rng.uniform(0.05, 0.4, 7))


def test_evaluation_matches_scipy_for_every_derivative(spline):
    reference = BSpline(spline.knots, spline.control_points, 3)
    t = np.linspace(0.0, spline.duration, 777)
    for order in range(4):
        assert np.allclose(spline.evaluate(t, order), reference(t, order), atol=1e-10)


def test_derivative_control_points_follow_eq_6_and_7(spline):
    cp, t = spline.control_points, spline.knots
    velocity, _, _ = spline.derivative(1)
    expected = np.array([3 * (cp[i + 1] - cp[i]) / (t[i + 4] - t[i + 1])
                         for i in range(len(cp) - 1)])
    assert np.allclose(velocity, expected)
    acceleration, _, _ = spline.derivative(2)
    assert np.allclose(acceleration, [2 * (velocity[i + 1] - velocity[i]) / (t[i + 4] - t[i + 2])
                                      for i in range(len(velocity) - 1)])
    # Convex hull: the curve's velocity never exceeds its largest control point.
    assert np.abs(spline.evaluate(np.linspace(0, spline.duration, 999), 1)).max() <= \
        np.abs(velocity).max() + 1e-12


def test_ends_are_exact_and_at_rest(spline):
    """Exactly: a move at rest at its ends reports zero speed and acceleration there."""
    rng = np.random.default_rng(5)
    for _ in range(200):
        points = rng.normal(size=(12, 3))
        points[1:3], points[-3:-1] = points[0], points[-1]
        curve = CubicBSpline.from_intervals(points, rng.uniform(0.001, 0.4, 9))
        q, qd, qdd = curve.evaluate_orders([0.0, curve.duration])
        assert np.array_equal(q, points[[0, -1]])
        assert not qd.any() and not qdd.any()
        # Elsewhere the same sums as ever: the derivatives just inside the ends are tiny.
        inside = curve.evaluate_orders([1e-9, curve.duration - 1e-9])
        assert np.abs(inside[1]).max() < 1e-6
    assert np.array_equal(spline.evaluate(spline.duration)[0], spline.control_points[-1])


def _station_corridor(cell, roadmap, start, goal):
    model = cell.motion_model
    path = find_path(roadmap, model, model.lipschitz, cell.stations[start].configs[0].q,
                     cell.stations[goal].configs[0].q).path
    return build_corridor(path, model.body_clearance(path), model.lipschitz)


def test_peak_speed_is_the_exact_maximum_on_each_piece(spline):
    boundaries, peaks = spline.pieces(subdivisions=4)
    assert boundaries[0] == 0.0 and boundaries[-1] == spline.duration
    for lo, hi, peak in zip(boundaries[:-1], boundaries[1:], peaks):
        sampled = np.abs(spline.evaluate(np.linspace(lo, hi, 4001), 1)).max(axis=0)
        assert np.all(sampled <= peak + 1e-12)
        assert np.allclose(sampled, peak, rtol=1e-5, atol=1e-9)


def test_collision_checks_are_at_most_one_milliradian_apart(spline):
    t = collision_times(spline)
    assert t[0] == 0.0 and t[-1] == spline.duration and np.all(np.diff(t) > 0)
    fine = np.concatenate([np.linspace(a, b, 50) for a, b in zip(t[:-1], t[1:])])
    q = spline.evaluate(fine).reshape(len(t) - 1, 50, 3)
    moved = np.abs(q - q[:, :1]).max()  # from each check to anywhere before the next
    assert moved <= COLLISION_STEP + 1e-12
    # Not wastefully dense: within 10 % of the joint travel in 1 mrad steps.
    travel = np.abs(np.diff(spline.evaluate(np.linspace(0, spline.duration, 100001)),
                            axis=0)).max(axis=1).sum()
    assert len(t) <= 1.1 * travel / COLLISION_STEP + 8 * len(spline.intervals)


def test_every_span_lies_in_a_safe_box_or_on_a_path_segment(default_cell, default_roadmap):
    corridor = _station_corridor(default_cell, default_roadmap, 'loadport1', 'loadlock2')
    points, path = corridor.control_points, corridor.path
    boxes = list(zip(path[1:-1], corridor.half_widths))
    for k in range(len(points) - 3):
        hull = points[k:k + 4]
        in_box = any(np.all(np.abs(hull - centre) <= half + 1e-12) for centre, half in boxes)
        on_segment = any(_on_segment(hull, a, b) for a, b in zip(path[:-1], path[1:]))
        assert in_box or on_segment, f'span {k} is neither in a box nor on a segment'
    # The boxes hold only free configurations (fcl on random points inside them).
    rng = np.random.default_rng(72)
    reference = default_cell.fcl_model()
    for centre, half in boxes:
        q = centre + rng.uniform(-1, 1, (300, 3)) * half
        assert not reference.in_collision_many(q).any()


def _on_segment(points, a, b):
    direction = b - a
    s = (points - a) @ direction / (direction @ direction)
    return np.all((s >= -1e-12) & (s <= 1 + 1e-12)) and np.allclose(
        a + s[:, None] * direction, points, atol=1e-12)


def test_constraint_gradients_are_exact(default_cell, default_roadmap):
    corridor = _station_corridor(default_cell, default_roadmap, 'loadport2', 'loadlock1')
    problem = TimingProblem(corridor.control_points, default_cell.robot)
    _check_gradients(problem, corridor, default_cell)
    # Every kind of row: jerk control points and the |a| limit too.
    robot = default_cell.robot
    limited = robot.with_limit_set(replace(
        robot.limit_set, joints=replace(robot.limits, jerk=np.array([84.0, 168.0, 126.0])),
        wafer=replace(robot.wafer_limit, norm=3.0)))
    _check_gradients(TimingProblem(corridor.control_points, limited), corridor, default_cell)


def _check_gradients(problem, corridor, default_cell):
    rng = np.random.default_rng(73)
    h = rng.uniform(0.05, 0.3, problem.spans)
    # Samples in every span, including the first and last three (clamped knots).
    span = np.concatenate([np.arange(problem.spans), rng.integers(0, problem.spans, 25)])
    samples = problem.samples(span, rng.random(len(span)))
    values, exact = problem.linearise(h, samples)
    assert np.allclose(values, problem.constraints(h, samples), rtol=1e-14, atol=1e-14)
    assert exact.shape == (len(values), problem.spans)
    eps = 1e-7
    numeric = np.stack([(problem.constraints(h + eps * e, samples)
                         - problem.constraints(h - eps * e, samples)) / (2 * eps)
                        for e in np.eye(problem.spans)], axis=1)
    assert np.allclose(exact, numeric, rtol=1e-5, atol=1e-4)
    # The per-sample windows give the same values as the whole spline.
    spline = CubicBSpline.from_intervals(corridor.control_points, h)
    t = spline.knots[span + 3] + h[span] * samples.fraction
    ax, ay = default_cell.robot.arm.wafer_acceleration(*spline.evaluate_orders(t)).T
    wafer = default_cell.robot.wafer_limit.xy
    expected = [1 - (ax / (MARGIN * wafer[0])) ** 2, 1 - (ay / (MARGIN * wafer[1])) ** 2]
    norm = problem.limit_set.wafer.norm
    if norm is not None:
        expected.append(1 - (ax ** 2 + ay ** 2) / (MARGIN * norm) ** 2)
    expected = np.concatenate(expected)
    assert np.allclose(problem.wafer_constraints(h, samples), expected, rtol=1e-9, atol=1e-9)


def test_lambda_start_is_feasible_and_the_optimum_is_faster(default_cell, default_roadmap):
    corridor = _station_corridor(default_cell, default_roadmap, 'loadport3', 'loadlock1')
    limits = default_cell.robot.limits
    problem = TimingProblem(corridor.control_points, default_cell.robot)
    timing = optimise(problem)
    assert timing.optimised and timing.scale >= 1.0
    for intervals in (timing.initial_intervals, timing.intervals):
        spline = CubicBSpline.from_intervals(corridor.control_points, intervals)
        velocity, acceleration = spline.derivative(1)[0], spline.derivative(2)[0]
        assert np.all(np.abs(velocity) <= limits.velocity + 1e-12)
        assert np.all(np.abs(acceleration) <= limits.acceleration + 1e-12)
        assert problem.dense_wafer_ratio(intervals)[0].max() <= MARGIN * (1 + 2e-4)
    assert timing.intervals.sum() < timing.initial_intervals.sum()


@pytest.mark.parametrize('iterations', [0, 5, 20, 10 ** 5])
def test_a_timing_stopped_at_its_deadline_meets_every_limit(monkeypatch, default_cell,
                                                            default_roadmap, iterations):
    # A clock that advances one second each time it is read: the solver, which reads it
    # before each iteration, stops after ``iterations`` of them, wherever it is then.
    corridor = _station_corridor(default_cell, default_roadmap, 'loadport3', 'loadlock1')
    problem = TimingProblem(corridor.control_points, default_cell.robot)
    optimum = optimise(problem).intervals.sum()
    clock = iter(range(10 ** 6))
    monkeypatch.setattr(timing_module.time, 'monotonic', lambda: float(next(clock)))
    stopped = optimise(problem, deadline=float(iterations))
    spline = CubicBSpline.from_intervals(corridor.control_points, stopped.intervals)
    ratios = limit_ratios(spline, default_cell.robot)
    assert max(ratios.values()) <= 1.0, ratios
    assert optimum - 1e-9 <= stopped.intervals.sum() <= stopped.initial_intervals.sum() + 1e-9
    if iterations == 10 ** 5:  # a deadline it never reaches changes nothing
        assert stopped.optimised and stopped.intervals.sum() == pytest.approx(optimum, abs=1e-12)


def _planner_corridor(cell, roadmap, start, goal):
    """Return the corridor the planner builds between two configurations (its defaults)."""
    model = cell.motion_model
    lipschitz = model.lipschitz
    path = shortcut(simplify(find_path(roadmap, model, lipschitz, start, goal).path), model,
                    lipschitz)
    return build_corridor(path, model.body_clearance(path), lipschitz)


def test_the_lambda_scaled_start_meets_every_limit_where_verification_checks(
        default_cell, default_roadmap):
    start, goal = PEAK_BETWEEN_SAMPLES
    corridor = _planner_corridor(default_cell, default_roadmap, start, goal)
    problem = TimingProblem(corridor.control_points, default_cell.robot)
    intervals, scale = scaled_start(problem)
    assert scale > 20.0
    checked = verify(CubicBSpline.from_intervals(problem.points, intervals), default_cell,
                     start, goal)
    assert checked.ok, checked.problems
    assert max(checked.ratios.values()) <= 1.0


def test_each_limit_ratio_scales_with_its_order_in_time(default_cell, spline):
    robot = default_cell.robot  # every limit
    robot = robot.with_limit_set(replace(robot.limit_set,
                                         wafer=replace(robot.wafer_limit, norm=3.0)))
    constraints = limit_constraints(robot.limit_set)
    orders = ratio_orders(constraints)
    assert set(limit_ratios(spline, robot)) == set(orders)
    slower = 1.7
    slowed = CubicBSpline.from_intervals(spline.control_points, slower * spline.intervals)
    # The same instants of both curves (none on a knot, where the jerk steps).
    t = np.random.default_rng(74).uniform(0.0, spline.duration, 500)
    ratios = [state_ratios(constraints, States(t, *states,
                                               robot.arm.wafer_acceleration(*states[:3])))
              for states in (spline.evaluate_orders(t, range(4)),
                             slowed.evaluate_orders(slower * t, range(4)))]
    for name, order in orders.items():
        assert ratios[1][name] == pytest.approx(ratios[0][name] / slower ** order, rel=1e-9)


def test_a_timing_over_the_limits_is_slowed_just_enough_to_meet_them(default_cell, spline):
    robot = default_cell.robot
    problem = TimingProblem(spline.control_points, robot)
    assert max(limit_ratios(spline, robot).values()) > 1.0
    intervals, factor = problem.meet_limits(spline.intervals)
    assert factor > 1.0 and np.array_equal(intervals, factor * spline.intervals)
    ratios = limit_ratios(CubicBSpline.from_intervals(spline.control_points, intervals), robot)
    # Met, and no slower than needed: the largest ratio comes to the margin (up to where
    # the check's instants fall on the slowed curve).
    assert MARGIN - 1e-3 < max(ratios.values()) <= 1.0
    # A timing that meets them is returned as it is.
    again, unchanged = problem.meet_limits(intervals)
    assert unchanged == 1.0 and np.array_equal(again, intervals)


def test_a_described_curve_comes_back_as_the_kind_it_names():
    rng = np.random.default_rng(5)
    points = np.vstack([np.zeros((2, 3)), rng.uniform(-1.0, 1.0, (4, 3)), np.ones((2, 3))])
    curve = CubicBSpline.from_intervals(points, rng.uniform(0.1, 0.5, len(points) - 3))
    data = json.loads(json.dumps(curve.describe()))  # plain data, as stored
    assert data['kind'] == 'cubic-b-spline'
    back = Trajectory.from_description(data)
    assert isinstance(back, CubicBSpline)
    assert np.array_equal(back.knots, curve.knots)
    assert np.array_equal(back.control_points, curve.control_points)
    # Written before kinds were named: a cubic B-spline.
    unnamed = {name: value for name, value in data.items() if name != 'kind'}
    assert np.array_equal(Trajectory.from_description(unnamed).knots, curve.knots)
    with pytest.raises(ValueError, match="unknown kind of curve 'quintic'"):
        Trajectory.from_description(dict(data, kind='quintic'))
    with pytest.raises(ValueError, match='degree 5'):
        Trajectory.from_description(dict(data, degree=5))
    t = np.linspace(0.0, curve.duration, 101)
    assert np.allclose(curve.backwards().evaluate(t), curve.evaluate(t[::-1]), atol=1e-12)
