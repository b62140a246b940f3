"""
A stored optimum moved to new ends: a warm start for the whole-curve optimisation.

**Beyond the paper.** A request near one answered before (the same stations re-taught a
little, joint angles near a station's pose, a move repeated with the ends nudged) has its
optimum near that answer's. ``moved_to`` takes the answer's curve to the request's ends:
each control point is shifted by a blend of the two ends' offsets, the start's for the
first three (the curve stays at rest there), the goal's for the last three, and between
them by the point's time along the curve (its Greville abscissa, the mean of its three
knots), through a quintic that leaves the ends at rest (``blend``); the span durations are
kept, then λ-scaled (Eq. 12, ``timing_problem.scaled_start``) so that the start meets
every limit. By time, not by the points' order: an optimum's spans range from a
millisecond to tenths of a second, and an offset added in equal steps per point moved the
points of a millisecond's span as far as those of a long one: its jerk 15 times the
limit there, λ-scaled to a draft 2.5 times the optimum's cycle time.
It is a draft only: not proven free of collision (its ends moved), it is optimised and
proven for the request like any start (``methods.WholeCurve``), and never returned as it is.
"""

import numpy as np

from wafer_planner_ros.trajectory.bspline import CubicBSpline, DEGREE
from wafer_planner_ros.trajectory.timing_problem import scaled_start, TimingProblem


def blend(u: np.ndarray) -> np.ndarray:
    """
    Return the share of the goal's offset at u in [0, 1] of the curve's time.

    10 u³ - 15 u⁴ + 6 u⁵: 0 at the start, 1 at the goal, its first two derivatives 0 at
    both, so the offsets add no speed or acceleration at the curve's ends.
    """
    return u ** 3 * (10.0 - 15.0 * u + 6.0 * u ** 2)


def moved_to(curve: CubicBSpline, start: np.ndarray, goal: np.ndarray, robot,
             timing) -> CubicBSpline:
    """Return ``curve`` (at rest at both ends) moved to ``start`` and ``goal``, λ-scaled."""
    points = np.array(curve.control_points, float)
    knots = np.asarray(curve.knots, float)
    greville = np.mean([knots[1 + k:len(points) + 1 + k] for k in range(DEGREE)], axis=0)
    along = blend(np.clip(greville / curve.duration, 0.0, 1.0))[:, None]
    points += (1.0 - along) * (np.asarray(start, float) - points[0]) \
        + along * (np.asarray(goal, float) - points[-1])
    points[:DEGREE], points[-DEGREE:] = start, goal  # exactly, whatever the rounding
    intervals, _ = scaled_start(TimingProblem(points, robot, timing), curve.intervals)
    return CubicBSpline.from_intervals(points, intervals)
