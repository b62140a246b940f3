"""
The whole-curve solver.

Its compiled rows agree with ``ShapeProblem.rows``; its SLSQP method solves a problem with a
known optimum.
"""

import numpy as np
import pytest

from wafer_planner_ros.planner import Planner
from wafer_planner_ros.trajectory import sqp
from wafer_planner_ros.trajectory.shape import _clearance_samples, ShapeProblem
from wafer_planner_ros.trajectory.tuning import ShapeSettings, TimingSettings


@pytest.fixture(scope='module')
def corridor(default_cell, default_roadmap):
    """Return the corridor curve (knot timing) of a pair with corners."""
    return Planner(default_cell, default_roadmap).plan('loadport1', 'loadlock2')


def test_solver_rows_are_the_rows_in_the_solvers_columns(default_cell, corridor):
    problem = ShapeProblem(corridor.trajectory, default_cell, ShapeSettings(), TimingSettings())
    spans = problem.spans
    wafer = (np.repeat(np.arange(spans), 3), np.tile(np.arange(3) / 3, spans))
    clearance = _clearance_samples(problem, np.repeat(np.arange(spans), 4),
                                   np.tile((np.arange(4) + 0.5) / 4, spans), every_body=True)
    rng = np.random.default_rng(0)
    points = problem.start.control_points.copy()
    points[3:-3] += rng.normal(0.0, 0.01, points[3:-3].shape)
    intervals = problem.start.intervals * rng.uniform(0.9, 1.1, spans) + 0.01
    scale = problem.start.intervals
    values, jacobian = problem.rows(points, intervals, wafer, clearance)
    free = ~problem.fixed
    expected = jacobian[:, np.concatenate([np.repeat(free, 3), np.ones(spans, bool)])]
    expected[:, -spans:] *= scale
    fast_values, fast_jacobian = problem.solver_rows(points, intervals, wafer, clearance, scale)
    assert np.allclose(fast_values, values, rtol=0, atol=1e-10)
    assert np.allclose(fast_jacobian, expected, rtol=1e-9, atol=1e-9)


def test_sqp_finds_the_optimum_of_a_small_problem():
    """Minimise x + y on the disc x^2 + y^2 <= 2 with x >= -0.5: (-0.5, -sqrt(1.75))."""
    def rows(x):
        return np.array([2.0 - x @ x]), -2.0 * x[None]

    result = sqp.solve(rows, np.ones(2), np.zeros(2), np.array([-0.5, -np.inf]),
                       np.full(2, np.inf), acc=1e-12)
    assert result.converged
    assert np.allclose(result.x, [-0.5, -np.sqrt(1.75)], atol=1e-6)
