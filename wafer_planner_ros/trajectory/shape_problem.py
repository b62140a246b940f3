"""
The whole-curve optimisation problem of one start curve: variables, rows and Jacobians.

Variables (``pack``): every control point but the three at each end (the complete stops)
and every span duration, relative to the start's. An end may be free (``FreeEnd``): the
curve then moves on there, along a given path at a speed v the optimiser chooses, and the
motion along that path takes a time tau >= time(v); the end's second and third control
points follow from v and its first two spans (the curve's velocity and acceleration there
are the path's at speed v), and v and tau are two more variables, tau in the objective.
A pinned end (``FreeEnd.pinned``, a divert's start) has its v and a given: the curve
starts in a moving robot's state whatever its spans.
Rows g >= 0 (``solver_rows``): the
velocity, acceleration (and jerk) control points, the wafer-centre acceleration at samples
and the clearance of a body (or a port margin: the cell's ``motion_model``, with a
keep-out round the mouth of every port the curve neither leaves nor enters,
``ShapeSettings.port_keep_out``) at samples, all with exact Jacobians (compiled: ``rows``;
clearance from the closest points and the body Jacobian). ``shape.optimise_shape`` solves
it.
"""

from dataclasses import dataclass
from typing import Callable, Optional, Sequence, Tuple

import numpy as np

from wafer_planner_ros.trajectory.bspline import CubicBSpline, DEGREE
from wafer_planner_ros.trajectory.constraints import ClearanceBound, joint_bounds
from wafer_planner_ros.trajectory.constraints import limit_constraints, position_bound
from wafer_planner_ros.trajectory.constraints import wafer_bound
from wafer_planner_ros.trajectory.tuning import ShapeSettings, TimingSettings

PINNED_MARGIN = 0.999
"""Of the timing's margin, what the rows of a problem with a pinned end keep (a curve
that cannot be slowed as a whole must meet every limit as solved)."""
KEEP_OUT_SAMPLES = 400
"""Configurations of a start curve checked against the keep-outs round the ports' mouths
(``breaks_keep_outs``)."""


@dataclass(frozen=True, eq=False)
class FreeEnd:
    """
    An end where the curve moves on along a path: q' = g1 v and q'' = g2 v^2 + g1 a there.

    At the start the curve leaves along the path (its distance s growing away from the
    curve: g1 = dq/ds, g2 = d2q/ds2 there) at speed v >= 0 and acceleration a along it,
    0 >= a >= ``-braking`` (still slowing down from the path, or not); at the goal it
    arrives along it, the same seen backwards in time. ``time(v, a)``: how long the motion
    along the path takes when the curve meets it so; ``reach(a)``: the highest v it can
    meet the curve at with a; ``time_slopes`` and ``reach_slope`` their derivatives;
    ``least_time``: no way along the path is faster.
    """

    g1: np.ndarray
    g2: np.ndarray
    braking: float
    time: Callable[[float, float], float]
    time_slopes: Callable[[float, float], Tuple[float, float]]
    reach: Callable[[float], float]
    reach_slope: Callable[[float], float]
    least_time: float
    pinned: Optional[Tuple[float, float]] = None
    """(v, a) the end has, whatever the optimiser does (``pinned_start``); None: free."""

    def state(self, points: np.ndarray, intervals: np.ndarray) -> tuple:
        """Return (v, a) of a curve's end (points and intervals in the end's own order)."""
        g1, g2, (h1, h2) = self.g1, self.g2, intervals[:2]
        norm = float(g1 @ g1)
        v = float(3.0 * (points[1] - points[0]) @ g1 / (h1 * norm))
        second = 6.0 / h1 * ((points[2] - points[1]) / (h1 + h2) - (points[1] - points[0]) / h1)
        return v, float((second - g2 * v * v) @ g1 / norm)

    def clipped(self, v: float, a: float) -> tuple:
        """Return (v, a) within the end's bounds (rounding at a bound taken back)."""
        if self.pinned is not None:
            return self.pinned
        a = min(max(a, -self.braking), 0.0)
        return min(max(v, 0.0), self.reach(a)), a

    def points(self, first: np.ndarray, h1: float, h2: float, v: float, a: float) -> tuple:
        """Return (P1, P2, their derivatives (2, 4, 3) by (h1, h2, v, a)) from P0."""
        g1, g2 = self.g1, self.g2
        p1 = first + h1 * v * g1 / 3.0
        curving = g2 * v * v + g1 * a
        bend = h1 * curving / 6.0 + v * g1 / 3.0
        p2 = p1 + (h1 + h2) * bend
        d1 = np.stack([v * g1 / 3.0, np.zeros(3), h1 * g1 / 3.0, np.zeros(3)])
        d2 = d1 + np.stack([bend + (h1 + h2) * curving / 6.0, bend,
                            (h1 + h2) * (h1 * v * g2 / 3.0 + g1 / 3.0),
                            (h1 + h2) * h1 * g1 / 6.0])
        return p1, p2, np.stack([d1, d2])


def refine(curve: CubicBSpline, spans: int) -> CubicBSpline:
    """Return the same curve with its longest spans halved until it has ``spans`` (Boehm)."""
    points, knots = curve.control_points, curve.knots
    while len(knots) - 2 * DEGREE - 1 < spans:
        widths = np.diff(knots[DEGREE:-DEGREE])
        s = int(np.argmax(widths))
        at, k = knots[DEGREE + s] + 0.5 * widths[s], DEGREE + s
        new = np.empty((len(points) + 1, points.shape[1]))
        new[:k - DEGREE + 1] = points[:k - DEGREE + 1]
        new[k + 1:] = points[k:]
        for i in range(k - DEGREE + 1, k + 1):
            alpha = (at - knots[i]) / (knots[i + DEGREE] - knots[i])
            # Between equal points (a stop) the point itself, exactly: rounding would set
            # the curve moving at its end.
            new[i] = np.where(points[i] == points[i - 1], points[i],
                              alpha * points[i] + (1.0 - alpha) * points[i - 1])
        points, knots = new, np.insert(knots, k + 1, at)
    return CubicBSpline(knots, points)


def keep_out_model(start: CubicBSpline, model, radius: float):
    """
    Return ``model`` with a disc of ``radius`` round other ports' mouths (the rows' model).

    Round the mouth of every port ``start`` neither leaves nor enters
    (``PortedModel.keeping_out``).
    """
    return model.keeping_out(radius, start.evaluate([0.0, start.duration]))


def breaks_keep_outs(start: CubicBSpline, model, radius: float) -> bool:
    """Return whether ``start`` comes within one of those discs, turned."""
    kept = keep_out_model(start, model, radius)
    return kept is not model and kept.port_model.breaks_keep_out(
        start.evaluate(np.linspace(0.0, start.duration, KEEP_OUT_SAMPLES)))


class ShapeProblem:
    """The whole-curve optimisation of one feasible start curve (see the module)."""

    def __init__(self, start: CubicBSpline, cell, shape: ShapeSettings,
                 timing: TimingSettings,
                 ends: Sequence[Optional[FreeEnd]] = (None, None), keep_out: bool = True,
                 constraints=None):
        """
        Refine the start curve's knots and set up the problem for ``cell``'s robot.

        ``ends``: the start's and the goal's ``FreeEnd``, or None where the curve stops.
        ``keep_out``: whether the rows keep the discs round the ports' mouths
        (``keep_out_model``); if not, the port rule alone. ``constraints``: the limits
        kept (default: those of the robot's set in use with the timing's margin).
        """
        self.cell, self.settings, self.timing = cell, shape, timing
        self.robot, self.model = cell.robot, cell.motion_model
        self.start = refine(start, shape.min_spans)
        self.clearance = ClearanceBound(
            keep_out_model(self.start, self.model, shape.port_keep_out) if keep_out
            else self.model)
        """The clearance the rows keep: of ``model`` (the proof's) with a keep-out round
        the mouth of every port the curve neither leaves nor enters (``geometry.ports``)."""
        self.count = len(self.start.control_points)
        self.spans = self.count - DEGREE
        self.pinned = any(end is not None and end.pinned is not None for end in ends)
        """Whether an end's motion is given (``FreeEnd.pinned``): then no curve of this
        problem may be slowed down as a whole (its motion there would change), and its
        rows keep ``PINNED_MARGIN`` more from every limit, which a solve's optimum, rounded
        to the solver's tolerance, can otherwise exceed by as much."""
        margin = timing.margin * (PINNED_MARGIN if self.pinned else 1.0)
        self.limits_kept = limit_constraints(self.robot.limit_set, margin) \
            if constraints is None else list(constraints)
        """The limits the rows keep (``trajectory.constraints``), then the clearance."""
        self._joints = joint_bounds(self.limits_kept)
        self.wafer = wafer_bound(self.limits_kept)
        """The wafer limit (loaded), or None: then wafer samples have no rows."""
        self.positions = position_bound(self.limits_kept)
        self.min_interval = timing.shortest(self.robot)
        self.fixed = np.zeros(self.count, dtype=bool)
        self.fixed[:DEGREE] = self.fixed[-DEGREE:] = True
        free = int((~self.fixed).sum())
        self._point_column = -np.ones((self.count, 3), np.int64)  # the solver's columns
        self._point_column[~self.fixed] = np.arange(3 * free).reshape(free, 3)
        self._duration_column = 3 * free + np.arange(self.spans)
        self.ends: Tuple[Optional[FreeEnd], ...] = tuple(ends)
        """The start's and the goal's free end, or None."""
        self._free_ends = [k for k, end in enumerate(self.ends) if end is not None]
        self.variables = 3 * free + self.spans + 3 * len(self._free_ends)
        """Columns of the solver: free points, durations, then (v, a, tau) per free end."""
        # The points a free end sets: each written to columns of its own after the
        # solver's, then folded into the columns of what sets it (``_fold``).
        self._raw_column = self._point_column.copy()
        for n, k in enumerate(self._free_ends):
            for m, index in enumerate(self._end_indices(k)[1:]):
                self._raw_column[index] = self.variables + 6 * n + 3 * m + np.arange(3)
        self._raw_width = self.variables + 6 * len(self._free_ends)

    @property
    def duration_columns(self) -> np.ndarray:
        """Return the solver's columns of the span durations."""
        return self._duration_column

    def drop_keep_outs(self) -> bool:
        """
        Let the rows keep the port rule alone; return whether they kept keep-outs.

        A start that passes turned nearer another port's mouth than its keep-out breaks
        the rows from the outset; where the solve that must push it out fails, the rule
        alone is solved instead.
        """
        if self.clearance.model is self.model:
            return False
        self.clearance = ClearanceBound(self.model)
        return True

    def _end_indices(self, k: int) -> tuple:
        """Return (P0, P1, P2) indices and the (h1, h2) span indices of end ``k``."""
        if k == 0:
            return 0, 1, 2
        return self.count - 1, self.count - 2, self.count - 3

    def _end_spans(self, k: int) -> tuple:
        return (0, 1) if k == 0 else (self.spans - 1, self.spans - 2)

    def _end_columns(self, n: int) -> tuple:
        """Return the (v, a, tau) columns of the n-th free end."""
        first = 3 * int((~self.fixed).sum()) + self.spans + 3 * n
        return first, first + 1, first + 2

    def speeds(self, points: np.ndarray, intervals: np.ndarray) -> list:
        """Return (v, a) of each free end of a curve (its points and durations)."""
        return [self.ends[k].state(points[list(self._end_indices(k))],
                                   intervals[list(self._end_spans(k))])
                for k in self._free_ends]

    def settled(self, points: np.ndarray, intervals: np.ndarray, speeds) -> np.ndarray:
        """Return the points with each free end's P1, P2 set by its (v, a) and spans."""
        points = np.array(points, float)
        for k, (v, a) in zip(self._free_ends, speeds):
            i0, i1, i2 = self._end_indices(k)
            h1, h2 = intervals[list(self._end_spans(k))]
            points[i1], points[i2], _ = self.ends[k].points(points[i0], h1, h2, v, a)
        return points

    def total(self, curve: CubicBSpline) -> float:
        """Return the curve's duration and the time along each free end's path (s)."""
        return self.total_of(curve.control_points, curve.intervals)

    def total_of(self, points: np.ndarray, intervals: np.ndarray) -> float:
        """Return ``total`` of a curve's control points and span durations."""
        speeds = self.speeds(points, intervals)
        return float(intervals.sum()) + sum(
            self.ends[k].time(*self.ends[k].clipped(v, a))
            for k, (v, a) in zip(self._free_ends, speeds))

    def bounds(self, lower: np.ndarray, upper: np.ndarray, scale: np.ndarray) -> tuple:
        """Return (lb, ub) of the solver's variables (points within ``lower``/``upper``)."""
        moving = int((~self.fixed).sum())
        ends_lb = np.array([x for k in self._free_ends
                            for x in (*self.ends[k].clipped(0.0, -self.ends[k].braking), 0.0)])
        ends_ub = np.array([x for k in self._free_ends
                            for x in (*self.ends[k].clipped(np.inf, 0.0), np.inf)])
        return (np.concatenate([np.tile(lower, moving), self.min_interval / scale, ends_lb]),
                np.concatenate([np.tile(upper, moving), np.full(self.spans, np.inf), ends_ub]))

    def objective(self, scale: np.ndarray) -> np.ndarray:
        """Return the objective's coefficients: the total time, the free ends' tau too."""
        moving = int((~self.fixed).sum())
        return np.concatenate([np.zeros(3 * moving), scale,
                               np.tile([0.0, 0.0, 1.0], len(self._free_ends))])

    # ------------------------------------------------------------ variables

    def pack(self, points: np.ndarray, intervals: np.ndarray, scale: np.ndarray):
        """
        Return x: the free control points, the durations relative to ``scale``, (v, tau).

        Each free end's (v, a) is the curve's own there, tau the time along its path then.
        """
        states = [self.ends[k].clipped(*state)
                  for k, state in zip(self._free_ends, self.speeds(points, intervals))]
        ends = [x for k, (v, a) in zip(self._free_ends, states)
                for x in (v, a, self.ends[k].time(v, a))]
        return np.concatenate([points[~self.fixed].ravel(), intervals / scale, ends])

    def unpack(self, x: np.ndarray, scale: np.ndarray) -> tuple:
        """Return (control points, durations) of x (a free end's points set by its v)."""
        points = self.start.control_points.copy()
        free = int((~self.fixed).sum())
        points[~self.fixed] = x[:3 * free].reshape(free, 3)
        intervals = x[3 * free:3 * free + self.spans] * scale
        return self.settled(points, intervals, self.speeds_of(x)), intervals

    def speeds_of(self, x: np.ndarray) -> list:
        """Return each free end's (v, a) in x."""
        return [(float(x[self._end_columns(n)[0]]), float(x[self._end_columns(n)[1]]))
                for n in range(len(self._free_ends))]

    def rows(self, x: np.ndarray, wafer, clearance, scale: np.ndarray) -> tuple:
        """Return ``solver_rows`` at the solver's x."""
        taus = [float(x[self._end_columns(n)[2]]) for n in range(len(self._free_ends))]
        return self.solver_rows(*self.unpack(x, scale), wafer, clearance, scale, taus)

    # ------------------------------------------------------------ rows

    def solver_rows(self, points, intervals, wafer, clearance, scale, taus=()) -> tuple:
        """
        Return the constraint values g >= 0 and their Jacobian by the solver's variables.

        Rows: the control points' (``rows.control_rows``), the wafer acceleration at the
        ``wafer`` (span, fraction) samples, then the clearance at the ``clearance``
        (span, fraction, body, kept) samples (``ClearanceBound``): (d - kept) / scale, by
        the body
        Jacobian through the basis weights; then tau - time(v) >= 0 per free end, ``taus``
        its tau. Columns as ``pack``: the free control points' coordinates, the durations
        relative to ``scale``, (v, tau) per free end.
        """
        points = np.ascontiguousarray(points, float)
        intervals = np.ascontiguousarray(intervals, float)
        scale = np.ascontiguousarray(scale, float)
        padded = np.concatenate([np.zeros(DEGREE), intervals, np.zeros(DEGREE)])
        (wafer_span, wafer_fraction), (span, fraction, body, kept) = wafer, clearance
        if self.wafer is None:
            wafer_span = wafer_span[:0]
        rows = sum(bound.row_count(self.count) for bound in self._joints) + len(span) + (
            0 if self.wafer is None else self.wafer.parts * len(wafer_span))
        values = np.empty(rows)
        jacobian = np.zeros((rows, self._raw_width))
        columns = (self._raw_column, self._duration_column, scale)
        row = 0
        for bound in self._joints:
            row = bound.write_rows(points, intervals, columns, values, jacobian, row)
        if len(wafer_span):
            row = self.wafer.write_rows(padded, points, wafer_span, wafer_fraction,
                                        np.asarray(self.robot.arm.link_lengths, float),
                                        columns, values, jacobian, row)
        if len(span):
            self.clearance.write_rows(padded, points, span, fraction, body, kept, columns,
                                      values, jacobian, row)
        if not self._free_ends:
            return values, jacobian
        return self._fold(points, intervals, scale, values, jacobian, taus)

    def _fold(self, points, intervals, scale, values, jacobian, taus) -> tuple:
        """
        Return the rows with each free end's points folded into what sets them, and its own.

        A free end's P1 and P2 are functions of its (v, a) and first two durations
        (``FreeEnd.points``): their columns' Jacobian goes to those by the chain rule.
        Then per free end: tau - time(v, a) >= 0, reach(a) - v >= 0, and its P1 and P2
        within the position limits (``PositionBound.inner``, as the free points).
        """
        lower, upper = self.positions.inner
        extra_values, extra = [], []
        for n, (k, state) in enumerate(zip(self._free_ends, self.speeds(points, intervals))):
            end = self.ends[k]
            i0, i1, i2 = self._end_indices(k)
            spans = self._end_spans(k)
            h1, h2 = intervals[list(spans)]
            v, a = end.clipped(*state)
            *_, derivatives = end.points(points[i0], h1, h2, *state)   # (2, 4 vars, 3)
            v_column, a_column, tau_column = self._end_columns(n)
            targets = [self._duration_column[spans[0]], self._duration_column[spans[1]],
                       v_column, a_column]
            factors = [scale[spans[0]], scale[spans[1]], 1.0, 1.0]
            for m, index in enumerate((i1, i2)):
                raw = jacobian[:, self._raw_column[index]]                    # (rows, 3)
                for target, factor, by in zip(targets, factors, derivatives[m]):
                    jacobian[:, target] += factor * (raw @ by)
            by_v, by_a = end.time_slopes(v, a)
            row = np.zeros(self.variables)
            row[tau_column], row[v_column], row[a_column] = 1.0, -by_v, -by_a
            extra_values.append(taus[n] - end.time(v, a))
            extra.append(row)
            if end.pinned is None:  # pinned: v stays, its rounding in state[0] aside
                row = np.zeros(self.variables)
                row[v_column], row[a_column] = -1.0, end.reach_slope(a)
                extra_values.append(end.reach(a) - state[0])
                extra.append(row)
            for m, index in enumerate((i1, i2)):
                for sign, bound in ((1.0, lower), (-1.0, upper)):
                    extra_values += list(sign * (points[index] - bound))
                    for joint in range(3):
                        row = np.zeros(self.variables)
                        for target, factor, by in zip(targets, factors, derivatives[m]):
                            row[target] += sign * factor * by[joint]
                        extra.append(row)
        return (np.concatenate([values, extra_values]),
                np.vstack([jacobian[:, :self.variables], extra]))

    def clearances(self, curve: CubicBSpline, span, fraction) -> np.ndarray:
        """Return every body's clearance and port margin (K, 4 + 4P) that the rows keep."""
        times = curve.breaks()[span] + curve.intervals[span] * fraction
        return self.clearance.model.body_clearance(curve.evaluate(times))
