"""
Time optimisation of the knot intervals (paper sections 4.3 and 5).

Variables: the durations h of the spline's spans. Objective: the total time sum(h)
(Eq. 11). Constraints, all as ``1 - (x / (MARGIN * limit))**2 >= 0``:

- joint velocity and acceleration control points (Eq. 6-8), and jerk control points when
  the cell sets a jerk limit; by the convex-hull property these bound the curve everywhere.
  Those below 70 % of their limit are left out of the solver (an active set) and added
  back when a solution brings them closer (measured on the 25 largest of 108 problems:
  the same cycle times as with 30 %, 30 % faster);
- the wafer-centre acceleration on x and y (Eq. 9), and on |a| when the cell sets
  ``wafer_acceleration_norm_limit``, at constraint samples: the paper's, at every knot;
- ``h >= MIN_INTERVAL``: Eq. 10 as printed would force every span to last the whole
  straight-line time, so it is read as a small positive lower bound.

The start point is the paper's λ-scaled uniform timing (Eq. 12), with λ computed from a
dense sample of the wafer acceleration so that it is feasible everywhere; SLSQP then solves
with exact gradients. They come by the complex step: every constraint is an analytic
function of h (the B-spline recursion and the kinematics use plain arithmetic), so
``Im g(h + i ε e_k) / ε`` is dg/dh_k to machine precision — there is no difference to cancel,
unlike finite differences. A wafer sample in span s depends on h_{s-2}..h_{s+2} only, so
its row of the Jacobian takes five complex evaluations of its own spline window (compiled,
``_wafer_rows``); the control-point rows are Eq. 6-7 differentiated in closed form
(``_control_rows``).

**Beyond the paper**: sampling the wafer acceleration at the knots lets it exceed the limit
between them. Every answer of the solver is therefore checked densely (every ``DENSE_STEP``
seconds, and every control point) and scaled by its own λ of Eq. 12, which makes it
feasible everywhere; if that scaling slows it by more than ``RESCALE_TOLERANCE``, the local
peaks over the limit become new samples and the problem is solved again (at most
``MAX_ROUNDS`` times). The fastest feasible answer is kept; only when the solver produced
nothing usable is the λ-scaled start returned, with the reason.

Limits are tightened by ``MARGIN`` inside the optimiser so that what lies between dense
samples stays below the true limits that verification applies.
"""

from dataclasses import dataclass
import logging
from typing import Optional

from numba import njit
import numpy as np
from scipy.optimize import minimize

from wafer_planner_ros.geometry.kinematics import wafer_acceleration_point
from wafer_planner_ros.trajectory.bspline import CubicBSpline, DEGREE, derivative_points
from wafer_planner_ros.trajectory.bspline import knots_from_intervals, padded_windows, WINDOW
from wafer_planner_ros.trajectory.bspline import window_states

logger = logging.getLogger(__name__)

MARGIN = 0.999
MIN_INTERVAL = 1e-3   # s
DENSE_STEP = 1e-3     # s
MAX_ROUNDS = 4  # 8 gave cycles at most 0.55 % shorter on 108 problems, at 1.4x the time
SAMPLES_PER_SPAN = 1
RESCALE_TOLERANCE = 1e-3  # stop adding samples once Eq. 12 would slow the answer < 0.1 %
FTOL = 1e-5  # s: SLSQP's stopping precision on the total time
# More samples only add constraints, so a round's optimum is about a lower bound of the
# final one: on the 3 test cells' station pairs it was at most 0.4 % above it.
GIVE_UP_MARGIN = 0.02
ACTIVE = 1.0 - 0.7 ** 2  # control-point constraints at 70 % of their limit or more are kept
COMPLEX_STEP = 1e-30  # s: far below rounding, so Im g / step is dg/dh exactly


@dataclass(frozen=True, eq=False)
class Timing:
    """The outcome of the time optimisation."""

    intervals: np.ndarray
    """Span durations (s) of the returned trajectory."""
    initial_intervals: np.ndarray
    """The λ-scaled start point (s)."""
    scale: float
    """λ of Eq. 12."""
    optimised: bool
    """False when the λ-scaled timing is returned instead (see ``message``)."""
    iterations: int
    """Solver iterations over all rounds."""
    rounds: int
    samples: int
    """Wafer-acceleration constraint samples in the last round."""
    message: str = ''


@dataclass(frozen=True, eq=False)
class Samples:
    """Instants where the wafer acceleration is constrained: fractions of spans."""

    span: np.ndarray
    fraction: np.ndarray

    def __len__(self) -> int:
        """Return the number of samples."""
        return len(self.span)


class TimingProblem:
    """The knot-interval optimisation of one set of control points."""

    def __init__(self, control_points: np.ndarray, robot):
        """Set up the problem for control points (n + 1, 3) of a cell's robot."""
        self.points = np.asarray(control_points, float)
        self.spans = len(self.points) - DEGREE
        self.arm = robot.arm
        self.limits = robot.limits
        self.wafer = robot.wafer_acceleration_limit
        self.wafer_norm = robot.wafer_acceleration_norm_limit
        # Velocity, acceleration (, jerk) limits and x, y, |a| wafer limits with the margin
        # (0: no |a| limit).
        orders = [self.limits.velocity, self.limits.acceleration]
        if self.limits.jerk is not None:
            orders.append(self.limits.jerk)
        self._control_limits = MARGIN * np.array(orders, float)
        self._wafer_limits = MARGIN * np.array([self.wafer[0], self.wafer[1],
                                                self.wafer_norm or 0.0])

    def samples(self, span: np.ndarray, fraction: np.ndarray) -> Samples:
        """Return the samples at ``fraction`` (0..1) of the given spans."""
        return Samples(span=np.asarray(span, np.int64), fraction=np.asarray(fraction, float))

    def derivatives(self, intervals) -> tuple:
        """
        Return (knots, [velocity, acceleration (, jerk)] control points) of a timing.

        Jerk control points come when the cell limits jerk.
        """
        knots = knots_from_intervals(np.ascontiguousarray(intervals, float))
        out = [derivative_points(self.points, knots, DEGREE)]
        out.append(derivative_points(out[0], knots[1:-1], DEGREE - 1))
        if self.limits.jerk is not None:
            out.append(derivative_points(out[1], knots[2:-2], DEGREE - 2))
        return knots, out

    def control_constraints(self, intervals) -> np.ndarray:
        """Return the control-point constraints g >= 0, velocity then acceleration (, jerk)."""
        return _control_rows(np.ascontiguousarray(intervals, float), self.points,
                             self._control_limits, False)[0]

    def wafer_constraints(self, intervals: np.ndarray, samples: Samples) -> np.ndarray:
        """Return the wafer constraints g >= 0 at the samples: x, y (, |a|), (c * K,)."""
        return self._wafer(intervals, samples, False)[0]

    def constraints(self, intervals, samples: Samples, rows=None) -> np.ndarray:
        """
        Return the constraint values g >= 0 with the margin.

        ``rows`` selects control-point constraints (a mask over ``control_constraints``);
        the wafer-acceleration constraints at the samples follow.
        """
        control = self.control_constraints(intervals)
        return np.concatenate([control if rows is None else control[rows],
                               self.wafer_constraints(intervals, samples)])

    def linearise(self, intervals: np.ndarray, samples: Samples, rows=None) -> tuple:
        """Return the constraint values and their exact Jacobian (rows, m)."""
        intervals = np.ascontiguousarray(intervals, float)
        control, control_jacobian = _control_rows(intervals, self.points,
                                                  self._control_limits, True)
        if rows is not None:
            control, control_jacobian = control[rows], control_jacobian[rows]
        values, jacobian = self._wafer(intervals, samples, True)
        return (np.concatenate([control, values]), np.vstack([control_jacobian, jacobian]))

    def _wafer(self, intervals: np.ndarray, samples: Samples, gradients: bool) -> tuple:
        """Return the wafer constraint values (c * K,) and, if asked, their Jacobian."""
        padded, windows = padded_windows(np.asarray(intervals, float), samples.span)
        values, local = _wafer_rows(padded, windows, self.points, samples.span,
                                    samples.fraction, self.arm.link_lengths,
                                    self._wafer_limits, gradients)
        parts = len(values)
        if not gradients:
            return values.ravel(), None
        # Each row has derivatives by h_{s-2}..h_{s+2}; those by the zero lengths beyond
        # the ends fall in the padding and are dropped.
        dense = np.zeros((parts * len(samples), len(padded)))
        np.put_along_axis(dense, np.tile(windows[:, 1:WINDOW - 1], (parts, 1)),
                          local.reshape(parts * len(samples), WINDOW - 2), axis=1)
        return values.ravel(), dense[:, DEGREE:-DEGREE]

    def dense_wafer_ratio(self, intervals: np.ndarray) -> tuple:
        """Return (ratio, span, fraction): the worst of x, y, |a| every DENSE_STEP seconds."""
        span, fraction = dense_grid(intervals)
        spline = CubicBSpline.from_intervals(self.points, intervals)
        t = spline.knots[span + DEGREE] + intervals[span] * fraction
        ax, ay = self.arm.wafer_acceleration_xy(*spline.evaluate_orders(t))
        ratio = np.maximum(np.abs(ax) / self.wafer[0], np.abs(ay) / self.wafer[1])
        if self.wafer_norm is not None:
            ratio = np.maximum(ratio, np.hypot(ax, ay) / self.wafer_norm)
        return ratio, span, fraction

    def scale_factor(self, intervals: np.ndarray, wafer_ratio=None) -> float:
        """
        Return λ of Eq. 12 for a timing (wafer acceleration from the dense grid).

        ``wafer_ratio``: the largest ``dense_wafer_ratio`` if the caller already has it.
        """
        ratios = [1.0]
        for order, (points, limit) in enumerate(zip(self.derivatives(intervals)[1],
                                                    self._control_limits)):
            peak = float(np.max(np.abs(points) / limit, initial=0.0))
            ratios.append(peak ** (1.0 / (order + 1)))  # speed scales 1/λ, accel 1/λ², ...
        if wafer_ratio is None:
            wafer_ratio = self.dense_wafer_ratio(intervals)[0].max()
        ratios.append(np.sqrt(float(wafer_ratio) / MARGIN))
        return max(ratios)


def dense_grid(intervals: np.ndarray, step: float = DENSE_STEP) -> tuple:
    """Return (span, fraction) of times at most ``step`` apart, including every knot."""
    counts = np.maximum(np.ceil(intervals / step).astype(int), 1)
    span = np.repeat(np.arange(len(intervals)), counts)
    fraction = (np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)) \
        / np.repeat(counts, counts)
    return np.append(span, len(intervals) - 1), np.append(fraction, 1.0)


def initial_intervals(problem: TimingProblem) -> np.ndarray:
    """
    Return the uniform timing of the paper's start point, before λ-scaling.

    The total is the straight-line time of the slowest joint, max_j |qG - qI|_j / LV_j (the
    paper prints min_j, which is zero when a joint does not move); at least 0.01 s.
    """
    travel = np.abs(problem.points[-1] - problem.points[0]) / problem.limits.velocity
    total = max(float(travel.max()), 0.01)
    return np.full(problem.spans, total / problem.spans)


def scaled_start(problem: TimingProblem) -> tuple:
    """Return the paper's feasible start point (Eq. 12): (intervals, λ)."""
    uniform = initial_intervals(problem)
    scale = problem.scale_factor(uniform)
    return scale * uniform, scale


def optimise(problem: TimingProblem, start=None, give_up_above=None) -> Optional[Timing]:
    """
    Return the optimised timing of the problem (see the module's description).

    ``start``: ``scaled_start(problem)`` if the caller already has it. ``give_up_above``:
    a cycle time (s) this problem need not beat; None is returned as soon as a round's
    optimum, whose samples are a subset of the final ones, exceeds it by more than
    ``GIVE_UP_MARGIN`` (the planner uses it to drop an elbow-branch combination that
    cannot win).
    """
    start, scale = start or scaled_start(problem)
    # The paper's samples, every knot, plus SAMPLES_PER_SPAN - 1 more inside each span.
    inside = np.arange(SAMPLES_PER_SPAN) / SAMPLES_PER_SPAN
    span = np.append(np.repeat(np.arange(problem.spans), len(inside)), problem.spans - 1)
    fraction = np.append(np.tile(inside, problem.spans), 1.0)
    # Control-point constraints far from their limit are left out until they come close.
    rows = problem.control_constraints(start) <= ACTIVE
    best, intervals, iterations = start, start, 0
    for rounds in range(1, MAX_ROUNDS + 1):
        result = _solve(problem, intervals, problem.samples(span, fraction), rows)
        logger.debug('round %d: %s (%d iterations, T = %.4f s)', rounds, result.message,
                     result.nit, result.x.sum())
        iterations += result.nit
        if not np.all(np.isfinite(result.x)):
            break
        intervals = np.maximum(result.x, MIN_INTERVAL)
        if give_up_above is not None and \
                intervals.sum() > (1.0 + GIVE_UP_MARGIN) * give_up_above:
            logger.debug('round %d: T = %.4f s cannot beat %.4f s', rounds, intervals.sum(),
                         give_up_above)
            return None
        # Eq. 12 applied to the solver's answer makes it feasible everywhere (dense check).
        ratio, dense_span, dense_fraction = problem.dense_wafer_ratio(intervals)
        rescale = problem.scale_factor(intervals, ratio.max())
        if rescale * intervals.sum() < best.sum():
            best = rescale * intervals
        if rescale <= 1.0 + RESCALE_TOLERANCE:
            return Timing(best, start, scale, True, iterations, rounds, len(span))
        # Between samples the limit was exceeded: sample the peaks and solve again.
        rows |= problem.control_constraints(intervals) <= ACTIVE
        peaks = _peaks_over(ratio, MARGIN * (1.0 + 2e-4))
        span = np.append(span, dense_span[peaks])
        fraction = np.append(fraction, dense_fraction[peaks])
    if best is start:
        message = f'solver failed: {result.message}' if not result.success else \
            'no answer of the solver, scaled to meet every limit, beat the start'
        logger.warning('time optimisation fell back to the λ-scaled timing: %s', message)
        return Timing(start, start, scale, False, iterations, rounds, len(span), message)
    return Timing(best, start, scale, True, iterations, rounds, len(span),
                  f'stopped after {rounds} rounds, rescaled by {rescale:.4f}')


def _peaks_over(ratio: np.ndarray, threshold: float) -> np.ndarray:
    """Return the indices of the local maxima of ``ratio`` that exceed ``threshold``."""
    padded = np.concatenate([[-np.inf], ratio, [-np.inf]])
    peak = (ratio >= padded[:-2]) & (ratio > padded[2:]) & (ratio > threshold)
    return np.nonzero(peak)[0]


def _solve(problem: TimingProblem, start: np.ndarray, samples: Samples, rows):
    """
    Run SLSQP from ``start``; the variables are the durations relative to ``start``.

    Relative variables (all 1 at the start) suit SLSQP's initial identity Hessian: measured
    on 30 random queries, 17 % fewer iterations and slightly shorter cycle times than with
    the durations themselves.
    """
    scale = start.copy()
    last = {}

    def linearised(x):  # SLSQP asks for values, then gradients, at each new point
        if last.get('x') is None or not np.array_equal(last['x'], x):
            values, jacobian = problem.linearise(x * scale, samples, rows)
            last.update(x=x.copy(), values=values, gradients=jacobian * scale)
        return last

    def values(x):
        return linearised(x)['values']

    def gradients(x):
        return linearised(x)['gradients']

    result = minimize(lambda x: float(x @ scale), np.ones_like(scale), jac=lambda x: scale,
                      method='SLSQP', bounds=[(MIN_INTERVAL / v, None) for v in scale],
                      constraints=[{'type': 'ineq', 'fun': values, 'jac': gradients}],
                      options={'maxiter': 200, 'ftol': FTOL})
    result.x = result.x * scale
    return result


@njit(cache=True, nogil=True)
def _wafer_rows(padded, windows, points, span, fraction, link_lengths, limits, gradients):
    """
    Return the wafer constraints (c, K) at the samples and, when ``gradients``, (c, K, 5).

    The derivatives are by h_{s-2}..h_{s+2} of each sample's span s, by the complex step.
    ``limits``: x, y, |a| limits with the margin (|a| absent when 0).
    """
    parts = 3 if limits[2] > 0.0 else 2
    values = np.empty((parts, len(span)))
    local = np.zeros((parts, len(span), WINDOW - 2))
    window = np.empty(WINDOW, dtype=np.complex128)
    for k in range(len(span)):
        h = padded[windows[k]]
        p = points[span[k]:span[k] + DEGREE + 1]
        if not gradients:
            state = window_states(h, p, fraction[k])
            g = _wafer_g(*wafer_acceleration_point(link_lengths, state[0], state[1],
                                                   state[2]), limits)
            for c in range(parts):
                values[c, k] = g[c]
            continue
        for d in range(WINDOW - 2):  # the real parts are the values: exact to rounding
            window[:] = h
            window[d + 1] += 1j * COMPLEX_STEP
            state = window_states(window, p, fraction[k])
            g = _wafer_g(*wafer_acceleration_point(link_lengths, state[0], state[1],
                                                   state[2]), limits)
            for c in range(parts):
                values[c, k] = g[c].real
                local[c, k, d] = g[c].imag / COMPLEX_STEP
    return values, local


@njit(cache=True, nogil=True)
def _wafer_g(ax, ay, limits):
    """Return the x, y and |a| constraint values g = 1 - (a / limit)^2 (float or complex)."""
    norm = 1.0 + 0.0 * ax
    if limits[2] > 0.0:
        norm = 1.0 - (ax * ax + ay * ay) / (limits[2] * limits[2])
    return (1.0 - (ax / limits[0]) ** 2, 1.0 - (ay / limits[1]) ** 2, norm)


@njit(cache=True, nogil=True)
def _control_rows(intervals, points, limits, gradients):
    """
    Return the control-point constraints (R,) and, when ``gradients``, their Jacobian (R, m).

    Rows: every velocity, then acceleration (then jerk) control point's joints, each
    ``1 - (p / limit)^2``; ``limits`` (orders, 3) hold the margin. Eq. 6-7 differentiated:
    D'_i = d (D_{i+1} - D_i) / w_i with w_i = h_{i+o-2} + ... + h_i for the o-th derivative
    points D (degree d = 3 - o), so dD'_i/dh_k = (d (dD_{i+1} - dD_i) - D'_i [k in w_i]) / w_i.
    """
    m, orders = len(intervals), len(limits)
    rows = 0
    for order in range(orders):
        rows += 3 * (len(points) - 1 - order)
    values = np.empty(rows)
    jacobian = np.zeros((rows, m if gradients else 0))
    knots = knots_from_intervals(intervals)
    current = points.copy()
    slope = np.zeros((len(points), 3, m))  # d(current)/dh
    row = 0
    for order in range(orders):
        degree = DEGREE - order
        n = len(current) - 1
        following = np.empty((n, 3))
        following_slope = np.zeros((n, 3, m))
        for i in range(n):
            width = knots[i + 4] - knots[i + 1 + order]
            for j in range(3):
                following[i, j] = degree * (current[i + 1, j] - current[i, j]) / width
            if gradients:
                for k in range(m):
                    inside = i + order - 2 <= k <= i
                    for j in range(3):
                        d = degree * (slope[i + 1, j, k] - slope[i, j, k])
                        if inside:
                            d -= following[i, j]
                        following_slope[i, j, k] = d / width
        for i in range(n):
            for j in range(3):
                ratio = following[i, j] / limits[order, j]
                values[row] = 1.0 - ratio * ratio
                if gradients:
                    for k in range(m):
                        jacobian[row, k] = -2.0 * ratio * following_slope[i, j, k] \
                            / limits[order, j]
                row += 1
        current, slope = following, following_slope
    return values, jacobian
