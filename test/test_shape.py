"""
The whole-curve optimisation.

Exact rows (and the solver's compiled copy of them), an unchanged curve after refinement,
its SLSQP method on a problem with a known optimum, and plans that pass the independent
check faster than the corridor curve.
"""

from independent import check
import numpy as np
import pytest

from wafer_planner_ros.cell.stations import station_pairs
from wafer_planner_ros.planner import Planner, PlannerSettings
from wafer_planner_ros.report import plan_json, roadmap_json
from wafer_planner_ros.roadmap.cache import load_or_build
from wafer_planner_ros.trajectory import sqp
from wafer_planner_ros.trajectory.shape import _clearance_samples, refine, ShapeProblem
from wafer_planner_ros.trajectory.tuning import ShapeSettings, TimingSettings


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


def test_every_row_and_its_jacobian_agree_with_finite_differences(default_cell, corridor):
    """A wrong clearance, wafer or control-point derivative (by P or by h) fails here."""
    problem, wafer, clearance, points, intervals = _perturbed(default_cell, corridor)
    spans = problem.spans
    values, jacobian = problem.rows(points, intervals, wafer, clearance)
    clearance_rows = slice(len(values) - len(clearance[0]), None)
    columns = np.concatenate([np.arange(3 * 3, 3 * (problem.count - 3)),  # free points
                              3 * problem.count + np.arange(spans)])       # durations
    step = 1e-6
    worst = 0.0
    for column in columns:
        up, down = [points.copy(), intervals.copy()], [points.copy(), intervals.copy()]
        if column < 3 * problem.count:
            up[0].flat[column] += step
            down[0].flat[column] -= step
        else:
            up[1][column - 3 * problem.count] += step
            down[1][column - 3 * problem.count] -= step
        difference = (problem.rows(*up, wafer, clearance)[0]
                      - problem.rows(*down, wafer, clearance)[0]) / (2.0 * step)
        error = np.abs(difference - jacobian[:, column]) / (1.0 + np.abs(jacobian[:, column]))
        worst = max(worst, float(error.max()))
    assert worst < 1e-6
    # The clearance rows move with the control points near them: not all zero.
    assert np.abs(jacobian[clearance_rows][:, columns]).max() > 0.1


def test_the_solver_rows_are_the_rows_in_the_solvers_columns(default_cell, corridor):
    problem, wafer, clearance, points, intervals = _perturbed(default_cell, corridor)
    spans, scale = problem.spans, problem.start.intervals
    values, jacobian = problem.rows(points, intervals, wafer, clearance)
    free = ~problem.fixed
    expected = jacobian[:, np.concatenate([np.repeat(free, 3), np.ones(spans, bool)])]
    expected[:, -spans:] *= scale
    fast_values, fast_jacobian = problem.solver_rows(points, intervals, wafer, clearance, scale)
    assert np.allclose(fast_values, values, rtol=0, atol=1e-10)
    assert np.allclose(fast_jacobian, expected, rtol=1e-9, atol=1e-9)


def test_the_sqp_finds_the_optimum_of_a_small_problem():
    """Minimise x + y on the disc x^2 + y^2 <= 2 with x >= -0.5: (-0.5, -sqrt(1.75))."""
    def rows(x):
        return np.array([2.0 - x @ x]), -2.0 * x[None]

    result = sqp.solve(rows, np.ones(2), np.zeros(2), np.array([-0.5, -np.inf]),
                       np.full(2, np.inf), acc=1e-12)
    assert result.converged
    assert np.allclose(result.x, [-0.5, -np.sqrt(1.75)], atol=1e-6)


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
