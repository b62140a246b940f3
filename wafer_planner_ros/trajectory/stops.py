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
the control points fixed, every limit met) from the legs' own durations, so that it takes
no longer than its legs together (``stopping_curve``). Like any curve, it is verified (and
proven collision-free, within every port's tolerances) before it is returned.
"""

import numpy as np

from wafer_planner_ros.trajectory.bspline import CubicBSpline, DEGREE
from wafer_planner_ros.trajectory.timing import optimise
from wafer_planner_ros.trajectory.timing_problem import scaled_start, TimingProblem
from wafer_planner_ros.trajectory.tuning import TimingSettings


def joined_points(legs) -> np.ndarray:
    """
    Return the control points of curves joined end to start, each pose they meet at rest.

    ``legs``: control point arrays (n_k, 3), each starting where the one before ends.
    Where two meet, their common pose stands exactly three times (the fewest that stop a
    cubic there with no acceleration): each leg's own repeats of it are replaced. Raises
    ValueError when a leg does not start where the one before ends.
    """
    legs = [np.asarray(leg, float) for leg in legs]
    parts = []
    for k, leg in enumerate(legs):
        if k and not np.array_equal(leg[0], legs[k - 1][-1]):
            raise ValueError(f'leg {k} starts at {leg[0].tolist()}, not where leg {k - 1} '
                             f'ends ({legs[k - 1][-1].tolist()})')
        first = _repeated(leg) if k else 0
        last = len(leg) - (_repeated(leg[::-1]) if k < len(legs) - 1 else 0)
        parts.append(leg[first:last])
        if k < len(legs) - 1:
            parts.append(np.repeat(leg[-1:], DEGREE, axis=0))
    return np.concatenate(parts)


def stopping_curve(legs, robot, settings: TimingSettings = TimingSettings()) -> CubicBSpline:
    """
    Return the legs' curves (each at rest at both ends) joined into one and timed.

    ``legs``: ``CubicBSpline``, in order. The durations are the paper's timing optimisation
    of the joined control points, from two starts, the faster answer kept: the legs' own
    span durations one after the other (``own_intervals``), and the paper's uniform start,
    each λ-scaled to meet every limit (``scaled_start``). The first differs from the legs
    only next to the stops, so the curve takes about as long as its legs or less (the
    optimiser keeps its start when it finds nothing faster); the second found a faster
    curve on some chains. The curve meets every limit of ``robot`` (its limit set's), as
    that optimisation's answers do.
    """
    points = joined_points([leg.control_points for leg in legs])
    problem = TimingProblem(points, robot, settings)
    own = own_intervals(legs, problem.spans)
    best = None
    for initial in ([own] if own is not None else []) + [None]:
        intervals = optimise(problem, scaled_start(problem, initial), quiet=True).intervals
        if best is None or intervals.sum() < best.sum():
            best = intervals
    return CubicBSpline.from_intervals(problem.points, best)


def own_intervals(legs, spans: int):
    """
    Return the legs' span durations one after the other, as the joined curve's ``spans``.

    A leg at rest on three equal control points at a stop gives the joined curve as many
    spans there as it has; one at rest on two (no stop of its acceleration) gives it one
    more, which gets the leg's shortest span next to it; one dwelling on more than three
    loses its spans of rest (those whose four control points are equal). None if the count
    still differs.
    """
    pieces = []
    for k, leg in enumerate(legs):
        points, own = leg.control_points, leg.intervals
        head = DEGREE - (_repeated(points) if k else DEGREE)
        tail = DEGREE - (_repeated(points[::-1]) if k < len(legs) - 1 else DEGREE)
        short = own[[0, -1]].min()
        own = own[max(-head, 0):len(own) - max(-tail, 0)]
        pieces += [np.full(max(head, 0), short), own, np.full(max(tail, 0), short)]
    joined = np.concatenate(pieces)
    return joined if len(joined) == spans else None


def _repeated(points: np.ndarray) -> int:
    """Return how many of the first points equal the first."""
    same = np.all(points == points[0], axis=1)
    return int(np.argmin(same)) if not same.all() else len(points)
