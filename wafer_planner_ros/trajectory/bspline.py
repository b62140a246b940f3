"""
Clamped cubic B-splines in time (paper section 4.2, Eq. 4-7).

The knots are a time sequence: four at 0, the interior times, four at the total time T, so
that the curve starts at the first control point and ends at the last. Derivatives are
B-splines of lower degree whose control points (Eq. 6-7) are
``CPV_i = 3 (CP_{i+1} - CP_i) / (t_{i+4} - t_{i+1})`` and so on; by the convex-hull
property bounding them bounds the derivative everywhere (Eq. 8).

A point in span s (between knots t_{s+3} and t_{s+4}) depends only on the control points
P_s..P_{s+3} and the knots t_s..t_{s+7}, i.e. on the seven durations h_{s-3}..h_{s+3}
around it (zero beyond the clamped ends): ``window_states`` evaluates it from that window
alone. It is compiled (numba) and plain arithmetic, so it also runs on complex durations:
that is how the time optimisation differentiates it (complex step).
"""

from dataclasses import dataclass
from functools import cached_property
from math import factorial
from typing import ClassVar, Mapping, Optional

import numpy as np

from wafer_planner_ros.kernels import kernel
from wafer_planner_ros.trajectory.curve import Trajectory

DEGREE = 3
WINDOW = 2 * DEGREE + 1
"""Durations a span's points depend on: h_{s-3}..h_{s+3}."""


@kernel(nogil=True)
def knots_from_intervals(intervals):
    """Return the clamped cubic knot vector of span durations h (s): m + 7 knots."""
    knots = np.zeros(len(intervals) + 2 * DEGREE + 1, dtype=intervals.dtype)
    for j in range(len(intervals)):
        knots[DEGREE + 1 + j] = knots[DEGREE + j] + intervals[j]
    knots[len(intervals) + DEGREE + 1:] = knots[len(intervals) + DEGREE]
    return knots


@kernel(nogil=True)
def derivative_points(points, knots, degree):
    """Return the control points (n - 1, d) of the derivative spline (Eq. 6-7)."""
    n = points.shape[0]
    width = knots[1 + degree:n + degree] - knots[1:n]
    return (points[1:] - points[:-1]) * degree / width.reshape(-1, 1)


def padded_windows(intervals: np.ndarray, span: np.ndarray) -> tuple:
    """Return (durations padded with three zeros at each end, window indices (K, 7))."""
    padded = np.concatenate([np.zeros(DEGREE), intervals, np.zeros(DEGREE)])
    return padded, np.asarray(span)[:, None] + np.arange(WINDOW)


@kernel(nogil=True)
def raise_degree(funcs, left, right, knots, t, j):
    """
    Turn the degree j - 1 basis functions at t (``funcs[:j]``) into those of degree j.

    One step of the Cox-de Boor recursion (The NURBS Book, A2.2) on local ``knots``, span
    t_3..t_4; ``left`` and ``right`` carry the distances to the knots between the steps.
    """
    left[j] = t - knots[DEGREE + 1 - j]
    right[j] = knots[DEGREE + j] - t
    saved = 0.0 * funcs[0]
    for r in range(j):
        temp = funcs[r] / (right[r + 1] + left[j - r])
        funcs[r] = saved + right[r + 1] * temp
        saved = left[j - r] * temp
    funcs[j] = saved


@kernel(nogil=True)
def window_states(h, points, fraction):
    """
    Return q, q', q'', q''' (4, 3) at ``fraction`` (0..1) of a span.

    ``h`` (7,): the durations h_{s-3}..h_{s+3} (float or complex); ``points`` (4, 3): the
    control points P_s..P_{s+3}. The derivative control points follow Eq. 6-7 and the
    basis functions the Cox-de Boor recursion (The NURBS Book, A2.2) on the local knots.
    """
    knots = np.zeros(WINDOW + 1, dtype=h.dtype)  # t_s..t_{s+7}, relative to t_s
    for j in range(WINDOW):
        knots[j + 1] = knots[j] + h[j]
    velocity = derivative_points(points, knots, DEGREE)
    acceleration = derivative_points(velocity, knots[1:-1], DEGREE - 1)
    t = knots[DEGREE] + h[DEGREE] * fraction
    left = np.zeros(DEGREE + 1, dtype=h.dtype)
    right = np.zeros(DEGREE + 1, dtype=h.dtype)
    funcs = np.zeros(DEGREE + 1, dtype=h.dtype)
    funcs[0] = 1.0
    out = np.zeros((DEGREE + 1, 3), dtype=h.dtype)
    for j in range(1, DEGREE + 1):
        raise_degree(funcs, left, right, knots, t, j)
        # Degree-j functions weight the control points of derivative 3 - j.
        for i in range(3):
            total = 0.0 * h[0]
            for r in range(j + 1):
                if j == 1:
                    total += funcs[r] * acceleration[r, i]
                elif j == 2:
                    total += funcs[r] * velocity[r, i]
                else:
                    total += funcs[r] * points[r, i]
            out[DEGREE - j, i] = total
    out[DEGREE] = derivative_points(acceleration, knots[2:-2], DEGREE - 2)[0]
    return out


@kernel(nogil=True)
def _states_many(padded, windows, points, span, fraction):
    """Return window_states for many (span, fraction) samples, (K, 4, 3)."""
    out = np.empty((len(span), DEGREE + 1, 3))
    for k in range(len(span)):
        out[k] = window_states(padded[windows[k]], points[span[k]:span[k] + DEGREE + 1],
                               fraction[k])
    return out


def states(control_points: np.ndarray, intervals: np.ndarray, span, fraction) -> np.ndarray:
    """Return q, q', q'', q''' (K, 4, 3) at ``fraction`` of each ``span``."""
    span = np.asarray(span, np.int64)
    padded, windows = padded_windows(np.asarray(intervals, float), span)
    # Contiguous arrays, as the kernel was compiled for (a reversed view would compile it
    # again for strided arrays).
    return _states_many(padded, windows, np.ascontiguousarray(control_points, float), span,
                        np.ascontiguousarray(fraction, float))


_FALLING = np.array([[factorial(j) / factorial(j - order) if j >= order else 0.0
                      for order in range(DEGREE + 1)] for j in range(DEGREE + 1)])
"""j! / (j - order)!: the factor of tau^(j - order) in the order-th derivative."""


@kernel(nogil=True)
def _horner(coefficients, starts, span, t, order):
    """Return the order-th derivative (N, 3) of the Taylor pieces at times t in ``span``."""
    out = np.empty((len(t), coefficients.shape[2]))
    for k in range(len(t)):
        s, tau = span[k], t[k] - starts[span[k]]
        for i in range(coefficients.shape[2]):
            value = coefficients[s, DEGREE, i] * _FALLING[DEGREE, order]
            for j in range(DEGREE - 1, order - 1, -1):
                value = value * tau + coefficients[s, j, i] * _FALLING[j, order]
            out[k, i] = value
    return out


@dataclass(frozen=True, eq=False)
class CubicBSpline(Trajectory):
    """A clamped cubic B-spline q(t) in joint space."""

    kind: ClassVar[str] = 'cubic-b-spline'
    starts_at_rest: ClassVar[bool] = True
    """Whether the curve must start at rest (``ill_formed``); a kind that continues a
    motion does not (``continuing.Continuing``)."""

    knots: np.ndarray
    """(n + 5,) times (s)."""
    control_points: np.ndarray
    """(n + 1, 3) joint angles (rad)."""

    @classmethod
    def from_intervals(cls, control_points: np.ndarray, intervals: np.ndarray):
        """Return the spline whose spans last ``intervals`` (s); needs len(cp) - 3 of them."""
        control_points = np.ascontiguousarray(control_points, float)
        intervals = np.ascontiguousarray(intervals, float)
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

    def evaluate_orders(self, t, orders=(0, 1, 2)) -> tuple:
        """
        Return the derivatives of the given orders at times t, each (len(t), 3).

        Each span is a cubic polynomial; its Taylor coefficients at the span's start come
        from the B-spline basis once (``_pieces``), then every time costs one Horner sum;
        at the ends, the derivative curves' end control points.
        """
        t = np.clip(np.atleast_1d(np.asarray(t, float)), 0.0, self.duration)
        starts, coefficients = self._pieces
        span = np.clip(np.searchsorted(starts, t, side='right') - 1, 0, len(starts) - 1)
        out = []
        # A clamped curve's derivatives at its ends are its derivative curves' end control
        # points: exact there (a curve at rest at an end is exactly at rest; the Horner sum
        # left rounding, 1e-16 rad/s^2); only where its spans begin at 0 and end at T
        # (otherwise it runs on, continuous).
        first = t <= 0.0 if starts[0] == 0.0 else np.zeros(len(t), bool)
        last = t >= self.duration if self.knots[-DEGREE - 1] == self.duration else \
            np.zeros(len(t), bool)
        for order in orders:
            values = _horner(coefficients, starts, span, t, order)
            if first.any() or last.any():
                ends = self.derivative(order)[0] if order else self.control_points
                values[first], values[last] = ends[0], ends[-1]
            out.append(values)
        return tuple(out)

    def ill_formed(self, start: np.ndarray, goal: np.ndarray) -> Optional[str]:
        """
        Return what makes the curve no clamped cubic at rest from start to goal, or None.

        Its knots must be finite, four more than the control points, the first four 0, the
        last four one time T and those between increasing (every span lasts); the control
        points must be finite, the first two exactly ``start`` and the last two exactly
        ``goal`` (equal neighbours: zero velocity at the ends), the second only where the
        kind starts at rest (``starts_at_rest``).
        """
        problem = self.structure_problem(len(np.asarray(start)))
        if problem is not None:
            return problem
        points = np.asarray(self.control_points)
        start, goal = np.asarray(start, float), np.asarray(goal, float)
        last = len(points) - 1
        at_rest = ': the motion does not {} at rest'
        for i, end, name, why in ((0, start, 'start', ''), (last, goal, 'goal', ''),
                                  (1, start, 'start', at_rest.format('start')),
                                  (last - 1, goal, 'goal', at_rest.format('end'))):
            if i == 1 and not self.starts_at_rest:
                continue  # its motion there is the caller's to compare (``verify``)
            if not np.array_equal(points[i], end):
                return f'control point {i} is {points[i].tolist()}, not the {name} ' \
                    f'{end.tolist()}{why}'
        return None

    def structure_problem(self, joints: int = 3) -> Optional[str]:
        """
        Return what makes the data no clamped cubic B-spline of ``joints`` joints, or None.

        Its knots must be finite, four more than the control points, the first four 0, the
        last four one time T and those between increasing (every span lasts); the control
        points finite.
        """
        knots, points = np.asarray(self.knots), np.asarray(self.control_points)
        if points.ndim != 2 or len(points) < DEGREE + 1 or points.shape[1] != joints:
            return (f'the control points have the shape {points.shape}, not (n >= '
                    f'{DEGREE + 1}, {joints})')
        if knots.shape != (len(points) + DEGREE + 1,):
            return (f'the curve has {knots.size} knots for {len(points)} control points, not '
                    f'{len(points) + DEGREE + 1}')
        bad = np.flatnonzero(~np.isfinite(knots))
        if len(bad):
            return f'knot {bad[0]} is {float(knots[bad[0]])}, not finite'
        if np.any(knots[:DEGREE + 1] != 0.0):
            return (f'the first four knots are {knots[:DEGREE + 1].tolist()}, not 0: the curve '
                    'does not start at t = 0 as a clamped cubic')
        if np.any(knots[-DEGREE - 1:] != knots[-1]):
            return (f'the last four knots are {knots[-DEGREE - 1:].tolist()}, not one time T: '
                    'the curve does not end as a clamped cubic')
        bad = np.flatnonzero(np.diff(knots[DEGREE:-DEGREE]) <= 0.0)
        if len(bad):
            i = DEGREE + bad[0] + 1
            return (f'knot {i} is {float(knots[i])}, not after knot {i - 1} '
                    f'({float(knots[i - 1])}): span {bad[0]} does not last')
        bad = np.flatnonzero(~np.all(np.isfinite(points), axis=1))
        if len(bad):
            return f'control point {bad[0]} is {points[bad[0]].tolist()}, not finite'
        return None

    def breaks(self) -> np.ndarray:
        """Return the knot times 0 = t_3 < ... < t_{n+1} = T between the spans."""
        return self.knots[DEGREE:-DEGREE]

    def peak_speed(self, a, b) -> np.ndarray:
        """
        Return the exact largest |q'_j| on each [a_k, b_k] (K, 3), each within one span.

        q' is a quadratic on a span, so its extreme on an interval is at an end or where
        q'' = 0.
        """
        starts, coefficients = self._pieces
        a, b = np.atleast_1d(np.asarray(a, float)), np.atleast_1d(np.asarray(b, float))
        span = np.clip(np.searchsorted(starts, 0.5 * (a + b), side='right') - 1, 0,
                       len(starts) - 1)
        c1, c2, c3 = (coefficients[span, k] for k in (1, 2, 3))                # (K, 3)
        low, high = (a - starts[span])[:, None], (b - starts[span])[:, None]

        def speed(tau):
            return np.abs(c1 + tau * (2.0 * c2 + 3.0 * c3 * tau))

        peaks = np.maximum(speed(low), speed(high))
        with np.errstate(divide='ignore', invalid='ignore'):
            turn = np.where(c3 != 0.0, -c2 / (3.0 * c3), -np.inf)              # q'' = 0
        inside = (turn > low) & (turn < high)
        return np.where(inside, np.maximum(peaks, speed(np.where(inside, turn, low))), peaks)

    def backwards(self) -> 'CubicBSpline':
        """Return the motion backwards in time, q(T - t): the same limits hold on it."""
        return CubicBSpline.from_intervals(self.control_points[::-1], self.intervals[::-1])

    def describe(self) -> dict:
        """Return the kind, the degree, the knots and the control points."""
        return {'kind': self.kind, 'degree': DEGREE, 'knots': self.knots.tolist(),
                'control_points': self.control_points.tolist()}

    @classmethod
    def described(cls, data: Mapping) -> 'CubicBSpline':
        """Return the spline ``describe`` gave (its degree, if given, must be 3)."""
        if data.get('degree', DEGREE) != DEGREE:
            raise ValueError(f"a cubic B-spline of degree {str(data['degree'])[:20]}")
        return cls(np.asarray(data['knots'], float), np.asarray(data['control_points'], float))

    @cached_property
    def _pieces(self) -> tuple:
        """Return (span start times (m,), Taylor coefficients (m, 4, 3) at those starts)."""
        intervals = self.intervals
        starts = self.knots[DEGREE:-DEGREE - 1]
        at_start = states(self.control_points, intervals, np.arange(len(intervals)),
                          np.zeros(len(intervals)))
        return starts, at_start / np.array([factorial(k) for k in range(DEGREE + 1)])[:, None]
