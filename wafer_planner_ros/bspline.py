"""
Clamped cubic B-splines in time (paper section 4.2, Eq. 4-7).

The knots are a time sequence: four at 0, the interior times, four at the total time T, so
that the curve starts at the first control point and ends at the last. Derivatives are
B-splines of lower degree whose control points (Eq. 6-7) are
``CPV_i = 3 (CP_{i+1} - CP_i) / (t_{i+4} - t_{i+1})`` and so on; by the convex-hull
property bounding them bounds the derivative everywhere (Eq. 8). The functions below are
written with plain arithmetic so that they also run on ``autodiff.Dual`` knots, which is
how the time optimisation gets its gradients.
"""

from dataclasses import dataclass

import numpy as np

from wafer_planner_ros.autodiff import Dual

DEGREE = 3


def knots_from_intervals(intervals):
    """Return the clamped cubic knot vector of span durations h (s): len(h) + 7 knots."""
    if isinstance(intervals, Dual):
        m = intervals.shape[0]
        return Dual(knots_from_intervals(intervals.v), _knot_jacobian(m))
    times = np.concatenate([[0.0], np.cumsum(intervals)])
    return np.concatenate([[0.0] * DEGREE, times, [times[-1]] * DEGREE])


def _knot_jacobian(m: int) -> np.ndarray:
    """Return d(knots)/d(intervals), (m + 7, m)."""
    cumulative = np.tril(np.ones((m, m)))
    return np.vstack([np.zeros((DEGREE + 1, m)), cumulative, np.repeat(cumulative[-1:],
                                                                       DEGREE, axis=0)])


def basis(knots, span: np.ndarray, t, degree: int) -> list:
    """
    Return the degree+1 non-zero basis functions at t (The NURBS Book, A2.2).

    ``span[s]`` is the knot index i with knots[i] <= t[s] < knots[i+1]; the functions are
    N_{i-degree}, ..., N_i, each an array (or Dual) over the samples.
    """
    return basis_levels(knots, span, t, degree)[degree]


def basis_levels(knots, span: np.ndarray, t, degree: int) -> list:
    """
    Return the non-zero basis functions of every degree 0..degree at t, from one recursion.

    Entry d holds N_{i-d,d}, ..., N_{i,d} on ``knots``; these are also the degree-d basis
    functions of the (degree - d)-th derivative spline, whose knots drop (degree - d) knots
    at each end, at its span i - (degree - d).
    """
    funcs = [np.ones_like(span, dtype=float)]
    levels = [list(funcs)]
    left, right = [None], [None]
    for j in range(1, degree + 1):
        left.append(t - knots[span + 1 - j])
        right.append(knots[span + j] - t)
        saved = 0.0
        for r in range(j):
            temp = funcs[r] / (right[r + 1] + left[j - r])
            funcs[r] = saved + right[r + 1] * temp
            saved = left[j - r] * temp
        funcs.append(saved)
        levels.append(list(funcs))
    return levels


def combine(funcs: list, points, span: np.ndarray, degree: int):
    """Return sum_r funcs[r] * points[span - degree + r] (points: (n, d) array or Dual)."""
    total = None
    for r, f in enumerate(funcs):
        term = points[span - degree + r] * _column(f)
        total = term if total is None else total + term
    return total


def _column(x):
    """Return x with a trailing axis of length 1."""
    return x.expand() if isinstance(x, Dual) else np.asarray(x)[..., None]


def derivative_points(points, knots, degree: int):
    """Return the control points of the derivative spline (Eq. 6-7; degree - 1)."""
    n = points.shape[0]
    width = knots[1 + degree:n + degree] - knots[1:n]
    return (points[1:] - points[:-1]) * degree / _column(width)


def find_span(knots: np.ndarray, t: np.ndarray, n_points: int, degree: int) -> np.ndarray:
    """Return the knot span index of each time (the last span includes the end time)."""
    span = np.searchsorted(knots, t, side='right') - 1
    return np.clip(span, degree, n_points - 1)


@dataclass(frozen=True, eq=False)
class CubicBSpline:
    """A clamped cubic B-spline q(t) in joint space."""

    knots: np.ndarray
    """(n + 5,) times (s)."""
    control_points: np.ndarray
    """(n + 1, 3) joint angles (rad)."""

    @classmethod
    def from_intervals(cls, control_points: np.ndarray, intervals: np.ndarray):
        """Return the spline whose spans last ``intervals`` (s); needs len(cp) - 3 of them."""
        control_points = np.asarray(control_points, float)
        intervals = np.asarray(intervals, float)
        if len(intervals) != len(control_points) - DEGREE:
            raise ValueError(f'{len(control_points)} control points need '
                             f'{len(control_points) - DEGREE} intervals, got {len(intervals)}')
        return cls(knots_from_intervals(intervals), control_points)

    @property
    def duration(self) -> float:
        """Return the total time T (s)."""
        return float(self.knots[-1])

    @property
    def intervals(self) -> np.ndarray:
        """Return the span durations (s)."""
        return np.diff(self.knots[DEGREE:-DEGREE])

    def derivative(self, order: int = 1):
        """Return (control points, knots, degree) of the order-th derivative."""
        points, knots, degree = self.control_points, self.knots, DEGREE
        for _ in range(order):
            points = derivative_points(points, knots, degree)
            knots, degree = knots[1:-1], degree - 1
        return points, knots, degree

    def evaluate(self, t, order: int = 0) -> np.ndarray:
        """Return q (order 0), q', q'' or q''' at times t (clipped to [0, T]), (len(t), 3)."""
        t = np.clip(np.atleast_1d(np.asarray(t, float)), 0.0, self.duration)
        points, knots, degree = self.derivative(order)
        span = find_span(knots, t, len(points), degree)
        if degree == 0:
            return points[span].copy()
        values = combine(basis(knots, span, t, degree), points, span, degree)
        if order == 0:
            # A clamped curve passes through its end points; make that exact, not rounded.
            values[t <= 0.0] = points[0]
            values[t >= self.duration] = points[-1]
        return values
