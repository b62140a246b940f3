"""
The whole-curve optimisation.

Exact rows (values checked against an independent evaluation, Jacobians against finite
differences), an unchanged curve after refinement,
its SLSQP method on a problem with a known optimum, and plans that pass the independent
check faster than the corridor curve.
"""

import dataclasses
from pathlib import Path
import time

from independent import check
import numpy as np
import pytest
from scipy.interpolate import BSpline

from wafer_planner_ros.cell.model import Cell
from wafer_planner_ros.cell.stations import station_pairs
from wafer_planner_ros.planner import Planner, PlannerSettings
from wafer_planner_ros.report import plan_json, roadmap_json
from wafer_planner_ros.roadmap.cache import load_or_build
from wafer_planner_ros.trajectory import methods, shape as shape_module, sqp
from wafer_planner_ros.trajectory.bspline import CubicBSpline
from wafer_planner_ros.trajectory.coarse import coarse_start, fitted_points
from wafer_planner_ros.trajectory.constraints import CLEARANCE_SCALE
from wafer_planner_ros.trajectory.proof import prove
from wafer_planner_ros.trajectory.shape import _clearance_samples, optimise_shape, Shaping
from wafer_planner_ros.trajectory.shape_problem import refine, ShapeProblem
from wafer_planner_ros.trajectory.timing_problem import TimingProblem
from wafer_planner_ros.trajectory.tuning import ShapeSettings, TimingSettings

CELL_DIR = Path(__file__).resolve().parents[1] / 'support' / 'cells'


@pytest.fixture(scope='module')
def corridor(default_cell, default_roadmap):
    """Return the corridor curve (knot timing) of a pair with corners."""
    return Planner(default_cell, default_roadmap).plan('loadport1', 'loadlock2')


def test_refinement_keeps_the_curve_exactly(corridor):
    curve = corridor.trajectory
    refined = refine(curve, 2 * len(curve.intervals) + 3)
    assert len(refined.intervals) == 2 * len(curve.intervals) + 3
    assert refined.duration == curve.duration
    t = np.linspace(0.0, curve.duration, 5001)
    for order in range(3):
        assert np.allclose(refined.evaluate(t, order), curve.evaluate(t, order), rtol=0,
                           atol=1e-9 * 10 ** order)


def test_refinement_keeps_the_stops_exactly():
    """Equal control points at the ends stay equal: rounding would set the curve moving."""
    rng = np.random.default_rng(2)
    for _ in range(100):
        points = rng.uniform(-2.0, 2.0, (4, 3))
        points = np.vstack([points[:1], points[:1], points, points[-1:], points[-1:]])
        intervals = rng.uniform(0.05, 0.5, len(points) - 3)
        intervals[[0, -1]] = rng.uniform(1.0, 2.0, 2)  # the longest: halved first
        refined = refine(CubicBSpline.from_intervals(points, intervals), len(intervals) + 4)
        assert np.all(refined.control_points[:3] == points[0])
        assert np.all(refined.control_points[-3:] == points[-1])
        assert refined.ill_formed(points[0], points[-1]) is None


def _perturbed(cell, corridor) -> tuple:
    """Return (problem, wafer samples, clearance samples, points, durations) off the start."""
    problem = ShapeProblem(corridor.trajectory, cell, ShapeSettings(), TimingSettings())
    spans = problem.spans
    wafer = (np.repeat(np.arange(spans), 3), np.tile(np.arange(3) / 3, spans))
    clearance = _clearance_samples(problem, np.repeat(np.arange(spans), 4),
                                   np.tile((np.arange(4) + 0.5) / 4, spans), every_body=True)
    rng = np.random.default_rng(0)
    points = problem.start.control_points.copy()
    points[3:-3] += rng.normal(0.0, 0.01, points[3:-3].shape)
    intervals = problem.start.intervals * rng.uniform(0.9, 1.1, spans) + 0.01
    return problem, wafer, clearance, points, intervals


def _rows(problem, x, wafer, clearance, scale):
    return problem.solver_rows(*problem.unpack(x, scale), wafer, clearance, scale)


def test_every_row_and_its_jacobian_agree_with_finite_differences(default_cell, corridor):
    """A wrong clearance, wafer or control-point derivative (by P or by h) fails here."""
    problem, wafer, clearance, points, intervals = _perturbed(default_cell, corridor)
    scale = problem.start.intervals
    x = problem.pack(points, intervals, scale)
    values, jacobian = _rows(problem, x, wafer, clearance, scale)
    step, worst = 1e-6, 0.0
    for column in range(len(x)):
        up, down = x.copy(), x.copy()
        up[column] += step
        down[column] -= step
        difference = (_rows(problem, up, wafer, clearance, scale)[0]
                      - _rows(problem, down, wafer, clearance, scale)[0]) / (2.0 * step)
        error = np.abs(difference - jacobian[:, column]) / (1.0 + np.abs(jacobian[:, column]))
        worst = max(worst, float(error.max()))
    assert worst < 1e-6
    # The clearance rows move with the control points near them: not all zero.
    clearance_rows = slice(len(values) - len(clearance[0]), None)
    assert np.abs(jacobian[clearance_rows]).max() > 0.1


def test_the_rows_are_the_limits_and_clearances_they_stand_for(default_cell, corridor):
    """Each row's value against the curve evaluated independently (scipy's B-spline)."""
    problem, wafer, clearance, points, intervals = _perturbed(default_cell, corridor)
    values, _ = problem.solver_rows(points, intervals, wafer, clearance,
                                    problem.start.intervals)
    curve = CubicBSpline.from_intervals(points, intervals)
    reference = BSpline(curve.knots, points, 3)
    robot, margin = default_cell.robot, TimingSettings().margin
    # Control points: velocity, acceleration, jerk, each 1 - (D / (margin limit))^2.
    control, derivative = [], reference
    for limit in (robot.limits.velocity, robot.limits.acceleration, robot.limits.jerk):
        derivative = derivative.derivative()
        inner = derivative.c[:len(derivative.t) - derivative.k - 1]
        control.append((1.0 - (inner / (margin * limit)) ** 2).ravel())
    control = np.concatenate(control)
    assert np.allclose(values[:len(control)], control, atol=1e-9)
    # The wafer acceleration on x and y at the samples.
    span, fraction = wafer
    t = curve.breaks()[span] + intervals[span] * fraction
    ax, ay = robot.arm.wafer_acceleration_xy(reference(t), reference(t, 1), reference(t, 2))
    limit = margin * robot.wafer_limit.xy
    expected = np.concatenate([1.0 - (ax / limit[0]) ** 2, 1.0 - (ay / limit[1]) ** 2])
    assert np.allclose(values[len(control):len(control) + len(expected)], expected, atol=1e-9)
    # Clearance: (d - kept) / CLEARANCE_SCALE for the body named, its port margins with the
    # keep-out round the mouths of the ports the curve neither leaves nor enters.
    span, fraction, body, kept = clearance
    t = curve.breaks()[span] + intervals[span] * fraction
    model = default_cell.motion_model.keeping_out(
        ShapeSettings().port_keep_out, reference([0.0, curve.duration]))
    distance = model.body_clearance(reference(t))[np.arange(len(t)), body]
    assert np.allclose(values[-len(t):], (distance - kept) / CLEARANCE_SCALE, atol=1e-9)


def test_the_sqp_finds_the_optimum_of_a_small_problem():
    """Minimise x + y on the disc x^2 + y^2 <= 2 with x >= -0.5: (-0.5, -sqrt(1.75))."""
    def rows(x):
        return np.array([2.0 - x @ x]), -2.0 * x[None]

    result = sqp.solve(rows, np.ones(2), np.zeros(2), np.array([-0.5, -np.inf]),
                       np.full(2, np.inf), acc=1e-12)
    assert result.converged
    assert np.allclose(result.x, [-0.5, -np.sqrt(1.75)], atol=1e-6)


def test_a_solve_started_from_a_nearby_solves_matrix_takes_fewer_iterations():
    """B kept from a solve of a nearby problem (the next round's): the same optimum, sooner."""
    axes = np.array([0.2, 3.0])   # an ellipse: the Lagrangian's Hessian far from the identity

    def rows(x):
        d = (x - centre) / axes
        return np.array([1.0 - d @ d]), (-2.0 * d / axes)[None]

    centre = np.zeros(2)
    bounds = (np.full(2, -np.inf), np.full(2, np.inf))
    first = sqp.solve(rows, np.ones(2), np.array([0.1, 0.5]), *bounds, acc=1e-12)
    centre = np.array([0.01, -0.2])
    start = first.x + np.array([0.02, 0.3])
    cold = sqp.solve(rows, np.ones(2), start, *bounds, acc=1e-12)
    warm = sqp.solve(rows, np.ones(2), start, *bounds, acc=1e-12, hessian=first.hessian)
    optimum = centre - axes ** 2 / np.linalg.norm(axes)
    assert cold.converged and warm.converged
    assert np.allclose(warm.x, optimum, atol=1e-6) and np.allclose(cold.x, optimum, atol=1e-6)
    assert warm.iterations < cold.iterations


def test_within_a_budget_a_refuted_round_starts_the_next_near_its_optimum(
        default_cell, corridor, monkeypatch):
    """
    The rounds after one the proof refuted: without a budget from the last proven curve.

    From the coarse curve of loadport1 -> loadlock2 with one clearance sample a span, the
    first rounds' optima are refuted. Without a budget the next round starts from the
    start again, with the identity (as the station table has always been planned); within
    one, from the refuted optimum with its round's matrix (``ShapeSettings.warm_rounds``).
    """
    starts = []
    real = shape_module._solve

    def spy(problem, current, wafer, clearance, deadline=None, hessian=None):
        starts.append((current is problem.start, hessian is not None))
        return real(problem, current, wafer, clearance, deadline, hessian)

    monkeypatch.setattr(shape_module, '_solve', spy)
    start = coarse_start(corridor.trajectory.control_points, 8, default_cell.robot,
                         TimingSettings())
    settings = ShapeSettings(min_spans=8, clearance_samples=1)
    unbudgeted = optimise_shape(start, default_cell, settings, proven=False)
    assert starts[:2] == [(True, False), (True, False)]   # refuted: from the start again
    assert not any(kept for _, kept in starts)
    starts.clear()
    budgeted = optimise_shape(start, default_cell, settings, proven=False,
                              deadline=time.monotonic() + 600.0)
    assert starts[0] == (True, False) and starts[1] == (False, True)
    for shaped in (unbudgeted, budgeted):
        assert prove(shaped.trajectory, default_cell.motion_model,
                     default_cell.motion_model.lipschitz).certified


@pytest.mark.slow
def test_every_station_pair_optimised_passes_the_independent_check(
        cell, roadmap, roadmap_cache):
    """Every station pair of every test cell, every elbow-branch combination a candidate."""
    info = roadmap_json(load_or_build(cell, cache_dir=roadmap_cache))
    corridor = Planner(cell, roadmap)
    planner = Planner(cell, roadmap, PlannerSettings(method='whole-curve'))
    for start, goal in station_pairs(cell):
        result = planner.plan(start, goal)
        ratios = check(cell, plan_json(result, info, cell.robot.joint_names), result.start_q,
                       result.goal_q)
        assert ratios['jerk'] <= 1.0 + 1e-6  # every test cell limits jerk
        proof = result.verification.proof
        assert proof.certified and result.metrics['method'] == 'whole-curve'
        assert result.cycle_time < 0.8 * corridor.plan(start, goal).cycle_time
        assert not result.warnings
        # No motion between the two configurations is faster than the joints allow.
        fastest = cell.robot.limits.shortest_motion(result.goal_q - result.start_q)
        assert result.cycle_time >= fastest.max()


def test_within_a_time_budget_each_solve_stops_sooner(default_cell, default_roadmap):
    """
    A deadline far off still changes the stopping precision (``budget_ftol``), no more.

    On a pair whose solves end at that precision (loadport1 -> loadlock2's end at their
    iteration limit, where the precision changes nothing).
    """
    corridor = Planner(default_cell, default_roadmap).plan('loadport3', 'loadlock2')
    exact = optimise_shape(corridor.trajectory, default_cell)
    budgeted = optimise_shape(corridor.trajectory, default_cell,
                              deadline=time.monotonic() + 600.0)
    assert exact.improved and budgeted.improved
    assert budgeted.iterations < exact.iterations
    # The coarser stop costs a little time: 0.13 % on this pair, a median of 0.24 % over
    # 60 random joint requests.
    assert exact.trajectory.duration <= budgeted.trajectory.duration \
        < 1.02 * exact.trajectory.duration


def test_the_coarse_curve_fits_the_polygon_at_rest_at_both_ends(default_cell):
    """A polygon on a smooth curve is fitted closely; the ends are three equal points."""
    u = np.linspace(0.0, 1.0, 40)
    polygon = np.stack([np.sin(2.0 * u), u * u - 1.0, 0.5 * np.cos(3.0 * u)], axis=1)
    points = fitted_points(polygon, 8)
    assert points.shape == (11, 3)
    assert np.all(points[:3] == polygon[0]) and np.all(points[-3:] == polygon[-1])
    curve = coarse_start(polygon, 8, default_cell.robot, TimingSettings())
    dense = curve.evaluate(np.linspace(0.0, curve.duration, 400))
    # It follows the polygon: its vertices lie far nearer the curve than the straight line
    # between its ends does.
    gaps = np.linalg.norm(dense[:, None, :] - polygon[None], axis=2).min(axis=0)
    chord = polygon[-1] - polygon[0]
    along = (polygon - polygon[0]) @ chord / (chord @ chord)
    straight = np.linalg.norm(polygon - polygon[0] - along[:, None] * chord, axis=1)
    assert gaps.max() < 0.25 * straight.max()
    # On a straight polygon the fit is the straight line itself.
    line = polygon[0] + np.linspace(0.0, 1.0, 7)[:, None] * chord
    fitted = fitted_points(line, 8)
    offsets = fitted - polygon[0]
    assert np.allclose(np.cross(offsets, chord), 0.0, atol=1e-12)
    assert curve.ill_formed(polygon[0], polygon[-1]) is None
    # λ-scaled: every limit met at the verification's times.
    problem = TimingProblem(curve.control_points, default_cell.robot, TimingSettings())
    assert problem.scale_factor(curve.intervals) <= 1.0 + 1e-9


def _colliding(cell, corridor) -> CubicBSpline:
    """Return the corridor curve with three control points at a colliding configuration."""
    points = corridor.trajectory.control_points.copy()
    # Three equal control points in the middle at a configuration that collides: the curve
    # passes through it.
    rng = np.random.default_rng(4)
    lower, upper = cell.robot.limits.position.T
    q = rng.uniform(lower, upper, (200, 3))
    middle = len(points) // 2
    points[middle - 1:middle + 2] = q[cell.clearance_model.clearance(q) <= 0.0][0]
    return CubicBSpline.from_intervals(points, corridor.trajectory.intervals)


def test_a_scan_finds_every_stretch_nearer_a_wall_than_the_samples_keep(
        default_cell, corridor):
    """What the samples of an unproven curve's next round are added at, besides the proof's."""
    curve = corridor.trajectory
    problem = ShapeProblem(curve, default_cell, ShapeSettings(clearance=0.05),
                           TimingSettings())
    kept = shape_module._kept(problem)
    times = shape_module._too_near(problem, curve)
    model = default_cell.motion_model
    assert len(times) % 3 == 0 and np.all((model.body_clearance(
        curve.evaluate(times)) < kept).any(axis=1))
    first, nearest, last = times.reshape(-1, 3).T
    assert np.all(first <= nearest) and np.all(nearest <= last)
    t = np.linspace(0.0, curve.duration, 20001)
    near = (model.body_clearance(curve.evaluate(t)) < kept).any(axis=1)
    assert 0 < near.sum() < len(t)
    step = shape_module.SCAN_STEP
    covered = ((t[near, None] >= first - step) & (t[near, None] <= last + step)).any(axis=1)
    assert covered.all()
    # Where nothing is to be kept, a curve proven free has no such stretch.
    free = ShapeProblem(curve, default_cell, ShapeSettings(clearance=0.0, port_kept=0.0),
                        TimingSettings())
    assert len(shape_module._too_near(free, curve)) == 0


def test_a_scan_of_a_curve_lasting_many_minutes_looks_at_a_bounded_number_of_configurations(
        default_cell, corridor, monkeypatch):
    """A failed solve's curve of half an hour: scanned as one of 40 s, and its walls found."""
    curve = corridor.trajectory
    slow = CubicBSpline.from_intervals(curve.control_points,
                                       curve.intervals * (1800.0 / curve.duration))
    problem = ShapeProblem(curve, default_cell, ShapeSettings(clearance=0.05),
                           TimingSettings())
    model = problem.model
    looked = []
    body_clearance = type(model).body_clearance

    def counted(self, q):
        looked.append(len(np.atleast_2d(q)))
        return body_clearance(self, q)

    monkeypatch.setattr(type(model), 'body_clearance', counted)
    times = shape_module._too_near(problem, slow)
    assert sum(looked) <= shape_module.SCAN_POINTS
    assert len(times) and np.all((model.body_clearance(slow.evaluate(times))
                                  < shape_module._kept(problem)).any(axis=1))


def test_an_unproven_start_is_never_returned(default_cell, corridor):
    """A start through a wall: only proven curves come back, or none at all."""
    model = default_cell.motion_model
    start = _colliding(default_cell, corridor)
    assert not prove(start, model, model.lipschitz).certified
    late = optimise_shape(start, default_cell, deadline=time.monotonic() - 1.0, proven=False)
    assert late.trajectory is None and not late.improved  # no time: nothing proven
    shaped = optimise_shape(start, default_cell, proven=False)
    assert shaped.trajectory is None or (
        shaped.improved and prove(shaped.trajectory, model, model.lipschitz).certified)


def test_from_an_unproven_start_a_failed_solve_ends_the_optimisation(default_cell, corridor,
                                                                     monkeypatch):
    """A solver failure with nothing proven is not solved again with more samples."""
    solves, limit = [], ShapeSettings().max_iterations

    def stopped(iterations, message):
        def solve(problem, start, *rest):
            solves.append(start)
            return shape_module._Solved(start.control_points, start.intervals, iterations,
                                        message, False)
        return solve

    start = _colliding(default_cell, corridor)
    monkeypatch.setattr(shape_module, '_solve', stopped(7, 'subproblem failed (flag -4)'))
    shaped = optimise_shape(start, default_cell, proven=False)
    assert shaped.trajectory is None and len(solves) == 1 and shaped.rounds == 1
    assert shaped.message == 'no curve was proven (subproblem failed (flag -4))'
    # At its iteration limit it is solved again with samples where the proof failed.
    solves.clear()
    monkeypatch.setattr(shape_module, '_solve', stopped(limit, 'iteration limit reached'))
    shaped = optimise_shape(start, default_cell, proven=False)
    assert shaped.trajectory is None and len(solves) == ShapeSettings().max_rounds


def test_without_a_proven_coarse_curve_the_corridor_curve_starts_the_fine_stage(
        default_cell, default_roadmap, monkeypatch):
    planner = Planner(default_cell, default_roadmap, PlannerSettings(method='whole-curve'))
    starts = []
    real = methods.optimise_shape

    def coarse_fails(start, cell, shape, *rest, **options):
        if not options.get('proven', True):
            return Shaping(None, False, 0, 1, shape.min_spans, 'no curve was proven')
        starts.append(start)
        return real(start, cell, shape, *rest, **options)

    monkeypatch.setattr(methods, 'optimise_shape', coarse_fails)
    result = planner.plan('loadport2', 'loadlock2', branches=(1, 1))
    corridor = Planner(default_cell, default_roadmap).plan('loadport2', 'loadlock2',
                                                           branches=(1, 1))
    # The fine stage started from the corridor curve with optimised knot times.
    assert np.array_equal(starts[0].control_points, corridor.trajectory.control_points)
    assert result.verification.ok and result.verification.proof.certified
    assert 'coarse_cycle_time' not in result.metrics
    assert not result.metrics['fine_from_unproven']
    assert result.cycle_time < 0.8 * corridor.cycle_time


@pytest.mark.slow
def test_a_coarse_optimum_the_proof_refutes_starts_the_fine_stage(roadmap_cache, monkeypatch):
    """
    The coarse stage converges into a wall between its samples: the fine stage proves it.

    The pillar cell, loaded, roadmap seed 0, loadport1 on the elbow-right branch to
    loadlock1 on the left (the transfer of the move between their insides), its coarse
    stage's tries with more samples left out. On the machine this was found on none of
    the coarse stage's optima was proven; on another since, by rounding, one of them
    was. So here the coarse stage's proof refutes every optimum (as it does where they
    cut a corner between samples): started from the last of them, the fine stage proves a
    curve no slower than the one it finds from the corridor curve, in fewer than half of
    its iterations (52 against 150 where this was found).
    """
    monkeypatch.setattr(methods, 'coarse_samples', lambda per_span, *_: per_span)
    real_shape, real_prove = methods.optimise_shape, shape_module.prove

    def refuted(*args, **options):
        if not options.get('first_proven'):
            return real_shape(*args, **options)   # the fine stage, proved as it is
        with monkeypatch.context() as coarse:
            coarse.setattr(shape_module, 'prove', lambda *proof: dataclasses.replace(
                real_prove(*proof), certified=False))
            return real_shape(*args, **options)

    monkeypatch.setattr(methods, 'optimise_shape', refuted)
    cell = Cell.from_yaml(CELL_DIR / 'pillar.yaml')
    cached = load_or_build(cell, seed=0, cache_dir=roadmap_cache)
    planner = Planner(cell, cached.roadmap, PlannerSettings(method='whole-curve'))
    start, goal = ([c.q for c in cell.stations[name].configs if c.elbow == elbow][0]
                   for name, elbow in (('loadport1', 1), ('loadlock1', -1)))
    warm = planner.plan(start, goal)
    assert warm.metrics['fine_from_unproven'] and 'coarse_cycle_time' not in warm.metrics
    assert warm.verification.ok and warm.verification.proof.certified and not warm.warnings
    check(cell, plan_json(warm, roadmap_json(cached), cell.robot.joint_names), start, goal)

    def refuted_forgotten(*args, **options):
        shaped = refuted(*args, **options)
        if options.get('first_proven') and shaped is not None:
            shaped = dataclasses.replace(shaped, unproven=None)
        return shaped

    monkeypatch.setattr(methods, 'optimise_shape', refuted_forgotten)
    cold = planner.plan(start, goal)
    assert not cold.metrics['fine_from_unproven'] and 'coarse_cycle_time' not in cold.metrics
    assert warm.metrics['shape_iterations'] < 0.5 * cold.metrics['shape_iterations']
    assert warm.cycle_time <= 1.005 * cold.cycle_time


def test_a_coarse_stage_is_tried_again_with_more_samples_only_when_it_proved_nothing(
        default_cell, default_roadmap, monkeypatch):
    tries = []
    real = methods.optimise_shape

    def recorded(start, cell, shape, *rest, **options):
        shaped = real(start, cell, shape, *rest, **options)
        if options.get('first_proven'):
            tries.append((shape.min_spans, shape.clearance_samples,
                          shaped is not None and shaped.trajectory is not None))
        return shaped

    monkeypatch.setattr(methods, 'optimise_shape', recorded)
    planner = Planner(default_cell, default_roadmap, PlannerSettings(method='whole-curve'))
    for start, goal in station_pairs(default_cell)[:4]:
        planner.plan(start, goal)
    assert tries
    for before, (spans, samples, _) in zip(tries, tries[1:]):
        if samples > ShapeSettings().clearance_samples:
            assert not before[2]   # a retry follows a try that proved nothing
            assert spans in (before[0], 2 * before[0])


def test_a_coarse_stage_that_proved_nothing_is_tried_again_but_not_within_a_budget(
        default_cell, default_roadmap, monkeypatch):
    samples = []
    real = methods.optimise_shape
    per_span = ShapeSettings().clearance_samples

    def first_try_fails(start, cell, shape, *rest, **options):
        if options.get('first_proven'):
            samples.append(shape.clearance_samples)
            if shape.clearance_samples == per_span:
                return Shaping(None, False, 0, 1, shape.min_spans, 'no curve was proven')
        return real(start, cell, shape, *rest, **options)

    monkeypatch.setattr(methods, 'optimise_shape', first_try_fails)
    planner = Planner(default_cell, default_roadmap, PlannerSettings(method='whole-curve'))
    budgeted = planner.plan('loadport2', 'loadlock2', branches=(1, 1), budget=0.12,
                            deadline=time.monotonic() + 60.0)
    assert samples and set(samples) == {per_span}
    assert budgeted.verification.ok and 'coarse_cycle_time' not in budgeted.metrics
    samples.clear()
    result = planner.plan('loadport2', 'loadlock2', branches=(1, 1))
    assert samples[0] == per_span and max(samples) > per_span
    assert result.verification.ok and 'coarse_cycle_time' in result.metrics


def test_the_fine_stage_never_returns_a_slower_curve_than_the_coarse_one(
        default_cell, default_roadmap, monkeypatch):
    planner = Planner(default_cell, default_roadmap, PlannerSettings(method='whole-curve'))
    made = []
    monkeypatch.setattr(methods.KnotTiming, 'finish', lambda *a, **k: made.append(a))
    result = planner.plan('loadport3', 'loadlock1')
    assert result.cycle_time <= result.metrics['coarse_cycle_time']
    assert result.verification.ok and not result.warnings
    assert made == []  # the corridor curve is made only when it is needed


def test_a_proven_curve_slower_than_an_unproven_start_is_not_kept(default_cell, corridor,
                                                                  monkeypatch):
    """A failed solve can end on a far slower curve, proven all the same: it is not kept."""
    def slower(problem, start, *rest):
        return shape_module._Solved(start.control_points, 3.0 * start.intervals, 5,
                                    'subproblem failed (flag -4)', False)

    monkeypatch.setattr(shape_module, '_solve', slower)
    shaped = optimise_shape(corridor.trajectory, default_cell, proven=False)
    assert shaped.trajectory is None and not shaped.improved


def test_an_answer_stopped_far_over_the_limits_is_not_checked_at_length(default_cell,
                                                                        corridor,
                                                                        monkeypatch):
    """
    A budget's answer far over the limits is dropped, not checked every millisecond.

    Stopped by the budget mid-solve, an answer 30 x too fast would scale to a curve far
    slower than the start: it cannot be kept.
    """
    def stopped(problem, start, *rest):
        return shape_module._Solved(start.control_points, start.intervals / 30.0, 3,
                                    'stopped: the time budget ran out', False)

    checked = []
    meet_limits = TimingProblem.meet_limits

    def spy(problem, intervals):
        checked.append(float(np.sum(intervals)))
        return meet_limits(problem, intervals)

    clock = iter([0.0] + [10.0] * 1000)  # the round starts in time; the budget then ends
    monkeypatch.setattr(shape_module, '_solve', stopped)
    monkeypatch.setattr(TimingProblem, 'meet_limits', spy)
    monkeypatch.setattr(shape_module.time, 'monotonic', lambda: next(clock))
    shaped = optimise_shape(corridor.trajectory, default_cell, deadline=5.0)
    assert checked == [] and shaped.rounds == 1
    assert not shaped.improved and shaped.message == 'the time budget ran out'
    # The start (refined: the same curve) is what it has.
    assert shaped.trajectory.duration == pytest.approx(corridor.trajectory.duration, abs=1e-12)


def test_a_budget_too_short_for_the_coarse_stage_still_gets_its_proven_curve(
        default_cell, default_roadmap):
    """The coarse stage runs on past the budget to its first proven curve (no deadline)."""
    planner = Planner(default_cell, default_roadmap, PlannerSettings(method='whole-curve'))
    corridor = Planner(default_cell, default_roadmap).plan('loadport1', 'loadlock2',
                                                           branches=(1, 1))
    late = planner.plan('loadport1', 'loadlock2', branches=(1, 1), budget=1e-6)
    assert 'coarse_cycle_time' in late.metrics and not late.warnings
    assert late.cycle_time == late.metrics['coarse_cycle_time']  # no time for the fine stage
    assert late.verification.ok and late.verification.proof.certified
    assert late.cycle_time < 0.8 * corridor.cycle_time


def test_a_budget_too_short_for_a_fine_stage_from_an_unproven_coarse_optimum_still_proves_it(
        default_cell, default_roadmap, monkeypatch):
    """
    Where the coarse stage proves nothing, the fine stage from its optimum runs on too.

    A coarse stage that proves nothing is stood in for (its proven curve handed on as its
    unproven optimum: under a node's deadline, some joint requests' coarse stages prove
    nothing by half-way to it). Within a budget spent at once, the fine stage from that
    optimum runs on past it to its first proven curve (no deadline here), where it once
    stopped at the budget and the answer was the corridor curve, twice as slow.
    """
    real = methods.optimise_shape

    def coarse_proves_nothing(start, cell, shape, *args, **options):
        shaped = real(start, cell, shape, *args, **options)
        if shape.min_spans <= ShapeSettings().coarse_spans and shaped is not None:
            shaped = dataclasses.replace(shaped, trajectory=None,
                                         unproven=shaped.trajectory or shaped.unproven)
        return shaped

    monkeypatch.setattr(methods, 'optimise_shape', coarse_proves_nothing)
    planner = Planner(default_cell, default_roadmap, PlannerSettings(method='whole-curve'))
    corridor = Planner(default_cell, default_roadmap).plan('loadport1', 'loadlock2',
                                                           branches=(1, 1))
    late = planner.plan('loadport1', 'loadlock2', branches=(1, 1), budget=1e-6)
    assert late.metrics['fine_from_unproven'] and not late.warnings
    assert late.verification.ok and late.verification.proof.certified
    assert late.cycle_time < 0.8 * corridor.cycle_time


def test_within_a_budget_no_combination_runs_past_it_once_another_has_an_answer(
        default_cell, default_roadmap, monkeypatch):
    """
    Anytime: with an answer in hand, a combination's optimisation ends at the budget.

    Only while no combination has a proven curve may one run on past the budget (to its
    first proven curve, up to half-way to the deadline); the others' optimisations, told
    the best so far (``give_up_above``), stop at the budget, and the best proven curve by
    then is the answer.
    """
    real, calls = methods.optimise_shape, []

    def spied(start, cell, shape, timing, give_up_above=None, deadline=None, *args,
              **options):
        calls.append((give_up_above, deadline))
        return real(start, cell, shape, timing, give_up_above, deadline, *args, **options)

    monkeypatch.setattr(methods, 'optimise_shape', spied)
    planner = Planner(default_cell, default_roadmap, PlannerSettings(method='whole-curve'))
    budget, begun = 1.0, time.monotonic()  # long enough for several combinations
    answer = planner.plan('loadport2', 'loadlock1', budget=budget,
                          deadline=time.monotonic() + 30.0)
    until = begun + budget
    bounded = [deadline for best, deadline in calls if best is not None]
    assert bounded, 'no combination was optimised with the best so far'
    assert all(deadline is not None and deadline <= until + 0.01 for deadline in bounded)
    assert answer.verification.ok and answer.verification.proof.certified
