"""
A curve that continues a motion: a move left in motion for a new goal, in one curve.

**Beyond the paper.** A move diverted while it moves can always stop on its own path and
then move from rest (``chained.Chained``), but the robot then stands still where it need
not. ``Continuing`` is a clamped cubic B-spline that starts in the moving robot's state
instead: its first control point is where the robot is, and its second and third are set
by the velocity and acceleration it has there and by the first two span durations (for a
clamped cubic, q'(0) = 3 (P1 - P0) / h1 and q''(0) depends on P0, P1, P2, h1, h2 alone),
so that the join is continuous in acceleration by construction, whatever the durations. It
ends at rest at its goal, as every curve does.

The whole-curve optimiser shapes it (``shape.optimise_shape``) with the start as a pinned
free end (``pinned_start``: the motion there given, not chosen), from a draft fitted to
the stop-then-move curve (``draft``): that draft is not proven (a fit cuts its corners),
so only a curve the optimiser proves is returned, and the answer is verified as every
answer is, its start motion compared with the moving robot's.
"""

from typing import ClassVar, Optional

import numpy as np

from wafer_planner_ros.trajectory.bspline import CubicBSpline, DEGREE, knots_from_intervals
from wafer_planner_ros.trajectory.coarse import fitted_between
from wafer_planner_ros.trajectory.curve import Trajectory
from wafer_planner_ros.trajectory.shape_problem import FreeEnd

FIT_SAMPLES = 600
"""Instants of the stop-then-move curve a draft is fitted to."""
LEAST_SPEED = 1e-6
"""rad/s: a motion slower than this at the start is at rest there (no direction to pin)."""


class Continuing(CubicBSpline):
    """A clamped cubic B-spline that starts in motion and ends at rest (the module)."""

    kind: ClassVar[str] = 'continuing-b-spline'
    starts_at_rest: ClassVar[bool] = False


def pinned_start(velocity: np.ndarray, acceleration: np.ndarray) -> Optional[FreeEnd]:
    """
    Return the start of a curve that must move so (``FreeEnd.pinned``), or None at rest.

    The direction of the velocity is the path (g1, unit), its norm the speed v; the
    acceleration is g2 v^2 + g1 a, a its part along g1. Nothing follows along that path:
    its time is zero.
    """
    velocity, acceleration = np.asarray(velocity, float), np.asarray(acceleration, float)
    speed = float(np.linalg.norm(velocity))
    if not speed > LEAST_SPEED:
        return None
    g1 = velocity / speed
    along = float(acceleration @ g1)
    g2 = (acceleration - g1 * along) / speed ** 2
    return FreeEnd(g1, g2, max(-along, 0.0), lambda v, a: 0.0, lambda v, a: (0.0, 0.0),
                   lambda a: speed, lambda a: 0.0, 0.0, pinned=(speed, along))


def draft(curve: Trajectory, velocity: np.ndarray, acceleration: np.ndarray,
          intervals: np.ndarray) -> Continuing:
    """
    Return the curve of span durations ``intervals`` nearest ``curve``, started as given.

    ``curve``: a motion from its start (moving with ``velocity`` and ``acceleration``) to
    rest at its end (e.g. the controlled stop, then the move from rest). The first three
    control points are the start's (the module), the last three the goal; the others
    minimise the squared distance to ``FIT_SAMPLES`` instants of ``curve``, the draft's
    time scaled to ``curve``'s.
    """
    intervals = np.asarray(intervals, float)
    q = curve.evaluate([0.0, curve.duration])
    h1, h2 = intervals[:2]
    count = len(intervals) + DEGREE
    points = np.empty((count, q.shape[1]))
    points[0] = q[0]
    points[1] = q[0] + h1 * np.asarray(velocity, float) / 3.0
    points[2] = points[1] + (h1 + h2) * (h1 * np.asarray(acceleration, float) / 6.0
                                         + np.asarray(velocity, float) / 3.0)
    points[-DEGREE:] = q[1]
    knots = knots_from_intervals(intervals)
    u = np.linspace(0.0, 1.0, FIT_SAMPLES)
    return Continuing(knots, fitted_between(knots / knots[-1], u,
                                            curve.evaluate(u * curve.duration), points))
