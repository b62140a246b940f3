"""
A stored optimum moved to new ends: a warm start for the whole-curve optimisation.

**Beyond the paper.** A request near one answered before (the same stations re-taught a
little, joint angles near a station's pose, a move repeated with the ends nudged) has its
optimum near that answer's. ``moved_to`` takes the answer's curve to the request's ends:
each control point is shifted by a blend of the two ends' offsets, the start's for the
first three (the curve stays at rest there), the goal's for the last three, in proportion
to the point's place along the curve between them; the span durations are kept, then
λ-scaled (Eq. 12, ``timing_problem.scaled_start``) so that the start meets every limit.
It is a draft only: not proven free of collision (its ends moved), it is optimised and
proven for the request like any start (``methods.WholeCurve``), and never returned as it is.
"""

import numpy as np

from wafer_planner_ros.trajectory.bspline import CubicBSpline, DEGREE
from wafer_planner_ros.trajectory.timing_problem import scaled_start, TimingProblem


def moved_to(curve: CubicBSpline, start: np.ndarray, goal: np.ndarray, robot,
             timing) -> CubicBSpline:
    """Return ``curve`` (at rest at both ends) moved to ``start`` and ``goal``, λ-scaled."""
    points = np.array(curve.control_points, float)
    count = len(points)
    inner = max(count - 2 * DEGREE + 1, 1)
    along = np.clip((np.arange(count) - (DEGREE - 1)) / inner, 0.0, 1.0)[:, None]
    points += (1.0 - along) * (np.asarray(start, float) - points[0]) \
        + along * (np.asarray(goal, float) - points[-1])
    points[:DEGREE], points[-DEGREE:] = start, goal  # exactly, whatever the rounding
    intervals, _ = scaled_start(TimingProblem(points, robot, timing), curve.intervals)
    return CubicBSpline.from_intervals(points, intervals)
