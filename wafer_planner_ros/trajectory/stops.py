"""
A motion that stops on its way: the curves of its legs joined into one curve.

A move into or out of a port can always be made as a controller without non-stop moves
makes it: retract out of the port to its retracted pose, stop, transfer, stop, extend into
the other port, each leg from rest to rest. Joined, that chain is one clamped cubic
B-spline: each leg's control points follow the last leg's, the pose where they meet
standing three times in a row (``joined_points``), so that the curve passes it at rest —
zero velocity and zero acceleration there, as the convex hull of its derivatives' control
points shows — and keeps to the convex hull of its own legs' control points everywhere
else. Its span durations are then optimised as the paper's timing does (``timing.optimise``:
the control points fixed, every limit met), so that it takes about as long as its legs
together. Like any curve, it is verified (and proven collision-free, within every port's
tolerances) before it is returned.
"""

import numpy as np

from wafer_planner_ros.trajectory.bspline import CubicBSpline, DEGREE
from wafer_planner_ros.trajectory.timing import optimise
from wafer_planner_ros.trajectory.timing_problem import scaled_start, TimingProblem
from wafer_planner_ros.trajectory.tuning import TimingSettings


def joined_points(legs) -> tuple:
    """
    Return the control points of curves joined end to start, each pose they meet at rest.

    ``legs``: control point arrays (n_k, 3), each starting where the one before ends.
    Where two meet, their common pose stands exactly three times (the fewest that stop a
    cubic there with no acceleration): each leg's own repeats of it are replaced. Returns
    (points (N, 3), the leg each point comes from (N,): a stop's three copies belong to the
    leg that ends there). Raises ValueError when a leg does not start where the one before
    ends.
    """
    legs = [np.asarray(leg, float) for leg in legs]
    parts, owners = [], []
    for k, leg in enumerate(legs):
        if k and not np.array_equal(leg[0], legs[k - 1][-1]):
            raise ValueError(f'leg {k} starts at {leg[0].tolist()}, not where leg {k - 1} '
                             f'ends ({legs[k - 1][-1].tolist()})')
        first = _repeated(leg) if k else 0
        last = len(leg) - (_repeated(leg[::-1]) if k < len(legs) - 1 else 0)
        parts.append(leg[first:last])
        if k < len(legs) - 1:
            parts.append(np.repeat(leg[-1:], DEGREE, axis=0))
        owners.append(np.full(sum(map(len, parts)) - sum(map(len, owners)), k))
    return np.concatenate(parts), np.concatenate(owners)


def stopping_curve(legs, robot, settings: TimingSettings = TimingSettings()) -> CubicBSpline:
    """
    Return the legs' curves (each at rest at both ends) joined into one and timed.

    ``legs``: ``CubicBSpline`` (or any curve with ``control_points`` and ``duration``), in
    order. The durations are the paper's timing optimisation of the joined control points,
    started from each leg's own duration spread evenly over its spans and λ-scaled to meet
    every limit (``scaled_start``: the paper's uniform start, spread over legs of very
    different lengths, led the optimiser to a curve 1.77 times as long as its legs once);
    the curve meets every limit of ``robot`` (its limit set's), as that optimisation's
    answers do.
    """
    points, owners = joined_points([leg.control_points for leg in legs])
    problem = TimingProblem(points, robot, settings)
    # Span s lies between points s + 1 and s + 2: the leg of point s + 1 owns it.
    span_owner = owners[1:1 + problem.spans]
    spans = np.bincount(span_owner, minlength=len(legs))
    durations = np.array([leg.duration for leg in legs])
    initial = np.maximum(durations[span_owner] / spans[span_owner], problem.min_interval)
    timing = optimise(problem, scaled_start(problem, initial))
    return CubicBSpline.from_intervals(problem.points, timing.intervals)


def _repeated(points: np.ndarray) -> int:
    """Return how many of the first points equal the first."""
    same = np.all(points == points[0], axis=1)
    return int(np.argmin(same)) if not same.all() else len(points)
