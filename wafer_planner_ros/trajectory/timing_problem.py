"""
The knot-interval optimisation problem of one curve (paper sections 4.3 and 5).

Variables: the durations h of the spline's spans. Objective: the total time sum(h)
(Eq. 11). Constraints, all as ``1 - (x / (margin * limit))**2 >= 0``: the joint velocity,
acceleration (and jerk) control points (Eq. 6-8), and the wafer-centre acceleration on x
and y (and |a|) at constraint samples (Eq. 9). ``Timing`` is what the optimiser returns.
"""

from dataclasses import dataclass
from typing import Optional

import numpy as np

from wafer_planner_ros.trajectory.bspline import CubicBSpline, DEGREE, derivative_points
from wafer_planner_ros.trajectory.bspline import knots_from_intervals, padded_windows, WINDOW
from wafer_planner_ros.trajectory.constraints import joint_bounds, limit_constraints
from wafer_planner_ros.trajectory.constraints import ratio_orders, wafer_bound
from wafer_planner_ros.trajectory.tuning import TimingSettings
from wafer_planner_ros.trajectory.verify import limit_ratios


@dataclass(frozen=True, eq=False)
class Timing:
    """The outcome of the time optimisation."""

    intervals: np.ndarray
    """Span durations (s) of the returned trajectory."""
    initial_intervals: np.ndarray
    """The λ-scaled start point (s)."""
    scale: float
    """λ of Eq. 12 (times the slowing that ``TimingProblem.meet_limits`` added)."""
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

    def __init__(self, control_points: np.ndarray, robot,
                 settings: TimingSettings = TimingSettings(), constraints=None):
        """
        Set up the problem for control points (n + 1, 3) of a cell's robot.

        ``constraints``: the limits kept (``trajectory.constraints``); default: those of
        ``robot``'s set in use with the settings' margin.
        """
        self.settings = settings
        self.min_interval = settings.shortest(robot)
        """s: the shortest span."""
        self.points = np.asarray(control_points, float)
        self.spans = len(self.points) - DEGREE
        self.robot = robot
        self.arm = robot.arm
        self.limit_set = robot.limit_set
        self.limits = robot.limits
        self.limits_kept = limit_constraints(robot.limit_set, settings.margin) \
            if constraints is None else list(constraints)
        self._joints = joint_bounds(self.limits_kept)
        self.wafer = wafer_bound(self.limits_kept)
        """The wafer limit (loaded), or None: then samples have no rows."""
        self._fixed = -np.ones((len(self.points), 3), np.int64)  # no control point moves

    def samples(self, span: np.ndarray, fraction: np.ndarray) -> Samples:
        """Return the samples at ``fraction`` (0..1) of the given spans."""
        keep = slice(None) if self.wafer is not None else slice(0)
        return Samples(span=np.asarray(span, np.int64)[keep],
                       fraction=np.asarray(fraction, float)[keep])

    def derivatives(self, intervals) -> tuple:
        """
        Return (knots, [velocity, acceleration (, jerk)] control points) of a timing.

        Jerk control points come when the cell limits jerk.
        """
        knots = knots_from_intervals(np.ascontiguousarray(intervals, float))
        out = [derivative_points(self.points, knots, DEGREE)]
        for order in range(2, len(self._joints) + 1):
            out.append(derivative_points(out[-1], knots[order - 1:1 - order],
                                         DEGREE + 1 - order))
        return knots, out

    def control_constraints(self, intervals) -> np.ndarray:
        """Return the control-point constraints g >= 0, velocity then acceleration (, jerk)."""
        return self._control(intervals, False)[0]

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
        control, control_jacobian = self._control(intervals, True)
        if rows is not None:
            control, control_jacobian = control[rows], control_jacobian[rows]
        values, jacobian = self._wafer(intervals, samples, True)
        return (np.concatenate([control, values]), np.vstack([control_jacobian, jacobian]))

    def _control(self, intervals, gradients: bool) -> tuple:
        """Return the control-point constraint values and, if asked, their Jacobian (R, m)."""
        intervals = np.ascontiguousarray(intervals, float)
        m = len(intervals)
        values = np.empty(sum(bound.row_count(len(self.points)) for bound in self._joints))
        jacobian = np.zeros((len(values), m if gradients else 0))
        columns, row = (self._fixed, np.arange(m), np.ones(m)), 0
        for bound in self._joints:
            row = bound.write_rows(self.points, intervals, columns, values, jacobian, row,
                                   gradients)
        return values, jacobian

    def _wafer(self, intervals: np.ndarray, samples: Samples, gradients: bool) -> tuple:
        """Return the wafer constraint values (c * K,) and, if asked, their Jacobian."""
        if self.wafer is None:
            return np.empty(0), np.zeros((0, len(intervals))) if gradients else None
        padded, windows = padded_windows(np.asarray(intervals, float), samples.span)
        values, local, _ = self.wafer.sample_values(padded, self.points, samples.span,
                                                    samples.fraction, self.arm.link_lengths,
                                                    gradients)
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
        """Return (ratio, span, fraction): the worst of x, y, |a| at every dense step."""
        span, fraction = dense_grid(intervals, self.settings.dense_step)
        spline = CubicBSpline.from_intervals(self.points, intervals)
        t = spline.knots[span + DEGREE] + intervals[span] * fraction
        if self.wafer is None:
            return np.zeros(len(span)), span, fraction
        ax, ay = self.arm.wafer_acceleration_xy(*spline.evaluate_orders(t))
        return self.wafer.ratio(ax, ay), span, fraction

    def scale_factor(self, intervals: np.ndarray, wafer_ratio=None) -> float:
        """
        Return λ of Eq. 12 for a timing (wafer acceleration from the dense grid).

        ``wafer_ratio``: the largest ``dense_wafer_ratio`` if the caller already has it.
        """
        ratios = [1.0]
        for bound, points in zip(self._joints, self.derivatives(intervals)[1]):
            # Speed scales 1/λ, acceleration 1/λ², ...
            ratios.append(bound.peak(points) ** (1.0 / bound.order))
        if wafer_ratio is None:
            wafer_ratio = self.dense_wafer_ratio(intervals)[0].max()
        ratios.append(np.sqrt(float(wafer_ratio) / self.settings.margin))
        return max(ratios)

    def meet_limits(self, intervals: np.ndarray) -> tuple:
        """
        Return (intervals, factor): the timing slowed by ``factor`` >= 1 to meet every limit.

        The limits are checked on the curve itself, at the verification's own times and by
        its own ratios (``verify.limit_ratios``): Eq. 12 takes the wafer acceleration at
        dense instants of the timing before it is scaled, λ times as far apart once it is,
        and a peak between them can exceed the limit (slightly). Each
        limit over 1 slows the curve so that its ratio, of order k in time
        (``constraints.ratio_orders``), comes to ``margin``: by (ratio / margin) ** (1 / k);
        the check is repeated, ``limit_tries`` times at most (the last slowing is then
        returned unchecked; verification reports whatever it still exceeds).
        """
        timed, factor = np.asarray(intervals, float), 1.0
        orders = ratio_orders(self.limits_kept)
        for _ in range(self.settings.limit_tries):
            ratios = limit_ratios(CubicBSpline.from_intervals(self.points, timed), self.robot,
                                  self.limits_kept)
            values = np.array(list(ratios.values()))
            if np.all(values <= 1.0) or not np.all(np.isfinite(values)):
                return timed, factor
            factor *= max((ratio / self.settings.margin) ** (1.0 / orders[name])
                          for name, ratio in ratios.items())
            timed = factor * np.asarray(intervals, float)
        return timed, factor


def dense_grid(intervals: np.ndarray, step: float) -> tuple:
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
    paper prints min_j, which is zero when a joint does not move); at least 0.01 s, and no
    span shorter than the shortest allowed.
    """
    travel = np.abs(problem.points[-1] - problem.points[0]) / problem.limits.velocity
    total = max(float(travel.max()), 0.01)
    return np.full(problem.spans, max(total / problem.spans, problem.min_interval))


def scaled_start(problem: TimingProblem, initial: Optional[np.ndarray] = None) -> tuple:
    """
    Return the paper's feasible start point (Eq. 12): (intervals, λ).

    λ of Eq. 12, then slowed further where the curve still exceeds a limit at the
    verification's times (``TimingProblem.meet_limits``): the start meets every limit
    exactly as verification checks it. ``initial``: the intervals scaled, in place of the
    paper's uniform ones (``initial_intervals``).
    """
    uniform = initial_intervals(problem) if initial is None else np.asarray(initial, float)
    scale = problem.scale_factor(uniform)
    start, slower = problem.meet_limits(scale * uniform)
    return start, scale * slower
