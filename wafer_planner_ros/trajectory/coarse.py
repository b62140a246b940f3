"""
The whole-curve optimisation's coarse stage: a curve of few spans, fitted to the corridor.

**Beyond the paper.** The whole-curve optimisation costs its iterations times the size of
its problem, and the corridor curve it used to start from has as many spans as the corridor
has control points (tens on the test cells' station pairs) and a cycle time far from the
optimum's. So the curve is first optimised with few spans (``ShapeSettings.coarse_spans``):
a clamped cubic B-spline with that many uniform spans, fitted by least squares to the
corridor's control polygon (at rest at both ends: three equal control points each), where
the polygon is parametrised by the square root of each side's length (a side is crossed in
a time that grows as the square root of its length when acceleration limits it), then
λ-scaled to meet every limit (Eq. 12). That start keeps every limit but is not proven free
of collision (a fit cuts the corridor's corners): the optimisation keeps its clearance rows
at ``ShapeSettings.clearance`` wherever it touches a wall, and only proven curves leave it.
Its optimum, refined (``shape_problem.refine``: the same curve, more spans), starts the
fine optimisation close to the answer.
"""

import numpy as np

from wafer_planner_ros.trajectory.bspline import CubicBSpline, DEGREE
from wafer_planner_ros.trajectory.timing_problem import scaled_start, TimingProblem

FIT_SAMPLES = 200
"""Points of the control polygon the coarse curve is fitted to."""


def fitted_points(polygon: np.ndarray, spans: int) -> np.ndarray:
    """
    Return the control points (spans + 3, 3) of the coarse curve fitted to a polygon.

    The first and last three are the polygon's ends (the curve starts and ends at rest);
    the others minimise the squared distance to ``FIT_SAMPLES`` points spread over the
    polygon by the square root of each side's length (see the module).
    """
    polygon = np.asarray(polygon, float)
    sides = np.linalg.norm(np.diff(polygon, axis=0), axis=1)
    keep = np.concatenate([[True], sides > 0.0])  # repeated vertices: one is enough
    polygon = polygon[keep]
    along = np.concatenate([[0.0], np.cumsum(np.sqrt(sides[sides > 0.0]))])
    along /= along[-1]
    u = np.linspace(0.0, 1.0, FIT_SAMPLES)
    targets = np.stack([np.interp(u, along, polygon[:, j]) for j in range(polygon.shape[1])],
                       axis=1)
    knots = np.concatenate([np.zeros(DEGREE), np.linspace(0.0, 1.0, spans + 1),
                            np.ones(DEGREE)])
    points = np.empty((spans + DEGREE, polygon.shape[1]))
    points[:DEGREE], points[-DEGREE:] = polygon[0], polygon[-1]
    return fitted_between(knots, u, targets, points)


def fitted_between(knots: np.ndarray, u: np.ndarray, targets: np.ndarray,
                   points: np.ndarray) -> np.ndarray:
    """
    Return ``points`` with all but the first and last three fitted to ``targets`` at ``u``.

    ``knots``: the curve's, on [0, 1]; ``u`` (k,) where ``targets`` (k, joints) lie; the
    first and last three ``points`` stay as given (the curve's ends), the others minimise
    the squared distance of the curve at ``u`` to ``targets``.
    """
    basis = _basis(knots, u)                                             # (k, points)
    points = np.array(points, float)
    free = slice(DEGREE, len(points) - DEGREE)
    fixed = basis[:, :DEGREE] @ points[:DEGREE] + basis[:, -DEGREE:] @ points[-DEGREE:]
    points[free] = np.linalg.lstsq(basis[:, free], targets - fixed, rcond=None)[0]
    return points


def coarse_start(polygon: np.ndarray, spans: int, robot, timing) -> CubicBSpline:
    """Return the coarse curve fitted to a polygon, λ-scaled to meet every limit."""
    points = fitted_points(polygon, spans)
    intervals, _ = scaled_start(TimingProblem(points, robot, timing))
    return CubicBSpline.from_intervals(points, intervals)


def _basis(knots: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Return every cubic B-spline basis function (len(knots) - 4) at u in [0, 1] (Cox-de Boor)."""
    last = len(knots) - 1
    # Degree 0: the span holding u (the last one holds u = 1).
    span = np.clip(np.searchsorted(knots, u, side='right') - 1, DEGREE, last - DEGREE - 1)
    values = np.zeros((len(u), last))
    values[np.arange(len(u)), span] = 1.0
    for degree in range(1, DEGREE + 1):
        raised = np.zeros((len(u), last - degree))
        for i in range(last - degree):
            left = knots[i + degree] - knots[i]
            right = knots[i + degree + 1] - knots[i + 1]
            if left > 0.0:
                raised[:, i] += (u - knots[i]) / left * values[:, i]
            if right > 0.0:
                raised[:, i] += (knots[i + degree + 1] - u) / right * values[:, i + 1]
        values = raised
    return values
