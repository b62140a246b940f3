"""
Clamped cubic B-splines in time (paper section 4.2, Eq. 4-7).

The knots are a time sequence: four at 0, the interior times, four at the total time T, so
that the curve starts at the first control point and ends at the last. Derivatives are
B-splines of lower degree whose control points (Eq. 6-7) are
``CPV_i = 3 (CP_{i+1} - CP_i) / (t_{i+4} - t_{i+1})`` and so on; by the convex-hull
property bounding them bounds the derivative everywhere (Eq. 8). The functions below take
knots and points with any leading (batch) axes and use plain arithmetic only, so they also
run on complex values: that is how the time optimisation differentiates them (complex step).
"""

from dataclasses import dataclass
from functools import cached_property
from math import factorial

import numpy as np

DEGREE = 3


def knots_from_intervals(intervals):
    """Return the clamped cubic knot vector of span durations h (s): (..., m + 7) knots."""
    intervals = np.asarray(intervals)
    times = np.cumsum(intervals, axis=-1)
    zeros = np.zeros(intervals.shape[:-1] + (DEGREE + 1,), dtype=times.dtype)
    return np.concatenate([zeros, times, np.repeat(times[..., -1:], DEGREE, axis=-1)], axis=-1)


def basis(knots, span: np.ndarray, t, degree: int) -> list:
    """
    Return the degree+1 non-zero basis functions at t (The NURBS Book, A2.2).

    ``span[s]`` is the knot index i with knots[i] <= t[s] < knots[i+1]; the functions are
    N_{i-degree}, ..., N_i, each an array over the samples (``knots`` (..., k) and ``t``
    (..., s) may have leading batch axes).
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
        left.append(t - knots[..., span + 1 - j])
        right.append(knots[..., span + j] - t)
        saved = 0.0
        for r in range(j):
            temp = funcs[r] / (right[r + 1] + left[j - r])
            funcs[r] = saved + right[r + 1] * temp
            saved = left[j - r] * temp
        funcs.append(saved)
        levels.append(list(funcs))
    return levels


def combine(funcs: list, points, span: np.ndarray, degree: int):
    """Return sum_r funcs[r] * points[span - degree + r] (points (..., n, d))."""
    total = None
    for r, f in enumerate(funcs):
        term = points[..., span - degree + r, :] * f[..., None]
        total = term if total is None else total + term
    return total


def derivative_points(points, knots, degree: int):
    """Return the control points (..., n - 1, d) of the derivative spline (Eq. 6-7)."""
    n = points.shape[-2]
    width = knots[..., 1 + degree:n + degree] - knots[..., 1:n]
    return (points[..., 1:, :] - points[..., :-1, :]) * degree / width[..., None]


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
        return self.evaluate_orders(t, (order,))[0]

    def evaluate_orders(self, t, orders=(0, 1, 2)) -> tuple:
        """
        Return the derivatives of the given orders at times t, each (len(t), 3).

        Each span is a cubic polynomial; its Taylor coefficients at the span's start come
        from the B-spline basis once (``_pieces``), then every time costs one Horner sum.
        """
        t = np.clip(np.atleast_1d(np.asarray(t, float)), 0.0, self.duration)
        starts, coefficients = self._pieces
        span = np.clip(np.searchsorted(starts, t, side='right') - 1, 0, len(starts) - 1)
        tau = (t - starts[span])[:, None]
        pieces = coefficients[span]
        out = []
        for order in orders:
            values = pieces[:, DEGREE] * (factorial(DEGREE) / factorial(DEGREE - order))
            for j in range(DEGREE - 1, order - 1, -1):
                values = values * tau + pieces[:, j] * (factorial(j) / factorial(j - order))
            if order == 0:
                # A clamped curve passes through its end points; make that exact.
                values[t <= 0.0] = self.control_points[0]
                values[t >= self.duration] = self.control_points[-1]
            out.append(values)
        return tuple(out)

    def peak_speed(self, subdivisions: int = 8) -> tuple:
        """
        Return (boundaries, peaks): each span cut into ``subdivisions`` equal pieces.

        ``boundaries`` (S + 1,) are the pieces' times and ``peaks`` (S, 3) the exact largest
        |q'_j| on each: q' is a quadratic on a span, so its extreme on a piece is at an end
        or where q'' = 0.
        """
        starts, coefficients = self._pieces
        steps = np.arange(subdivisions + 1) / subdivisions
        tau = steps[None, :, None] * self.intervals[:, None, None]          # (m, P + 1, 1)
        c1, c2, c3 = (coefficients[:, None, k] for k in (1, 2, 3))          # (m, 1, 3)
        speed = np.abs(c1 + tau * (2.0 * c2 + 3.0 * c3 * tau))               # (m, P + 1, 3)
        peaks = np.maximum(speed[:, :-1], speed[:, 1:])
        with np.errstate(divide='ignore', invalid='ignore'):
            turn = np.where(c3 != 0.0, -c2 / (3.0 * c3), -1.0)               # q'' = 0
        inside = (turn > tau[:, :-1]) & (turn < tau[:, 1:])
        extreme = np.abs(c1 + turn * (2.0 * c2 + 3.0 * c3 * turn))
        peaks = np.where(inside, np.maximum(peaks, extreme), peaks)
        boundaries = (starts[:, None] + tau[:, :-1, 0]).ravel()
        return np.append(boundaries, self.duration), peaks.reshape(-1, 3)

    @cached_property
    def _pieces(self) -> tuple:
        """Return (span start times (m,), Taylor coefficients (m, 4, 3) at those starts)."""
        starts = self.knots[DEGREE:-DEGREE - 1]
        coefficients = np.stack([self._from_basis(starts, k) / factorial(k)
                                 for k in range(DEGREE + 1)], axis=1)
        return starts, coefficients

    def _from_basis(self, t: np.ndarray, order: int) -> np.ndarray:
        """Return the order-th derivative at times t from the B-spline basis (Eq. 4-7)."""
        points, knots, degree = self.derivative(order)
        span = find_span(knots, t, len(points), degree)
        if degree == 0:
            return points[span].copy()
        return combine(basis(knots, span, t, degree), points, span, degree)
