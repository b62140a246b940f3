"""
The whole-curve optimisation problem of one start curve: variables, rows and Jacobians.

Variables (``pack``): every control point but the three at each end (the complete stops)
and every span duration, relative to the start's. Rows g >= 0 (``solver_rows``): the
velocity, acceleration (and jerk) control points, the wafer-centre acceleration at samples
and the clearance of a body (or a port margin: the cell's ``motion_model``) at samples,
all with exact Jacobians (compiled: ``rows``;
clearance from the closest points and the body Jacobian). ``shape.optimise_shape`` solves
it.
"""

import numpy as np

from wafer_planner_ros.trajectory.bspline import CubicBSpline, DEGREE
from wafer_planner_ros.trajectory.rows import control_row_count, control_rows, sample_rows
from wafer_planner_ros.trajectory.rows import scatter_rows
from wafer_planner_ros.trajectory.tuning import ShapeSettings, TimingSettings

CLEARANCE_SCALE = 0.01
"""m: clearance rows are (d - kept) / this, of the order of the other rows."""


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


class ShapeProblem:
    """The whole-curve optimisation of one feasible start curve (see the module)."""

    def __init__(self, start: CubicBSpline, cell, shape: ShapeSettings,
                 timing: TimingSettings):
        """Refine the start curve's knots and set up the problem for ``cell``'s robot."""
        self.cell, self.settings, self.timing = cell, shape, timing
        self.robot, self.model = cell.robot, cell.motion_model
        self.start = refine(start, shape.min_spans)
        self.count = len(self.start.control_points)
        self.spans = self.count - DEGREE
        self._control_limits = self.robot.limits.rows(timing.margin)
        wafer = self.robot.wafer_limit
        self.wafer_limited = wafer is not None
        """Whether the wafer limit applies (loaded): if not, wafer samples have no rows."""
        self._wafer_limits = wafer.rows(timing.margin) if wafer else np.zeros(3)
        self.min_interval = timing.shortest(self.robot)
        self.fixed = np.zeros(self.count, dtype=bool)
        self.fixed[:DEGREE] = self.fixed[-DEGREE:] = True
        free = int((~self.fixed).sum())
        self._point_column = -np.ones((self.count, 3), np.int64)  # the solver's columns
        self._point_column[~self.fixed] = np.arange(3 * free).reshape(free, 3)
        self._duration_column = 3 * free + np.arange(self.spans)

    # ------------------------------------------------------------ variables

    def pack(self, points: np.ndarray, intervals: np.ndarray, scale: np.ndarray):
        """Return x: the free control points, then the durations relative to ``scale``."""
        return np.concatenate([points[~self.fixed].ravel(), intervals / scale])

    def unpack(self, x: np.ndarray, scale: np.ndarray) -> tuple:
        """Return (control points, durations) of x."""
        points = self.start.control_points.copy()
        free = int((~self.fixed).sum())
        points[~self.fixed] = x[:3 * free].reshape(free, 3)
        return points, x[3 * free:] * scale

    # ------------------------------------------------------------ rows

    def solver_rows(self, points, intervals, wafer, clearance, scale) -> tuple:
        """
        Return the constraint values g >= 0 and their Jacobian by the solver's variables.

        Rows: the control points' (``rows.control_rows``), the wafer acceleration at the
        ``wafer`` (span, fraction) samples, then the clearance at the ``clearance``
        (span, fraction, body, kept) samples: (d - kept) / CLEARANCE_SCALE, by the body
        Jacobian through the basis weights. Columns as ``pack``: the free control points'
        coordinates, then the durations relative to ``scale``.
        """
        points = np.ascontiguousarray(points, float)
        intervals = np.ascontiguousarray(intervals, float)
        scale = np.ascontiguousarray(scale, float)
        padded = np.concatenate([np.zeros(DEGREE), intervals, np.zeros(DEGREE)])
        (wafer_span, wafer_fraction), (span, fraction, body, kept) = wafer, clearance
        if not self.wafer_limited:
            wafer_span = wafer_span[:0]
        parts = 3 if self._wafer_limits[2] > 0.0 else 2
        control = control_row_count(self.count, len(self._control_limits))
        rows = control + parts * len(wafer_span) + len(span)
        values = np.empty(rows)
        jacobian = np.zeros((rows, 3 * int((~self.fixed).sum()) + self.spans))
        columns = (self._point_column, self._duration_column, scale)
        row = control_rows(points, intervals, self._control_limits, *columns, values, jacobian)
        links = np.asarray(self.robot.arm.link_lengths, float)
        if len(wafer_span):
            local = sample_rows(padded, points, wafer_span, wafer_fraction, links,
                                self._wafer_limits, False)
            scatter_rows(jacobian, values, row, *local, wafer_span, *columns)
            row += parts * len(wafer_span)
        if len(span):
            q, q_h, q_p = sample_rows(padded, points, span, fraction, links,
                                      self._wafer_limits, True)
            distance, gradient = self.model.body_clearance_gradient(np.ascontiguousarray(q.T))
            k = np.arange(len(span))
            distance, gradient = distance[k, body], gradient[k, body]      # (K,), (K, 3)
            by_h = np.einsum('ikd,ki->kd', q_h, gradient)
            by_p = q_p[0, :, :, 0][:, :, None] * gradient[:, None, :]      # (K, 4, 3)
            scatter_rows(jacobian, values, row, ((distance - kept) / CLEARANCE_SCALE)[None],
                         by_h[None] / CLEARANCE_SCALE, by_p[None] / CLEARANCE_SCALE, span,
                         *columns)
        return values, jacobian

    def clearances(self, curve: CubicBSpline, span, fraction) -> np.ndarray:
        """Return every body's clearance and port margin (K, 4 + 2P) at samples of a curve."""
        times = curve.breaks()[span] + curve.intervals[span] * fraction
        return self.model.body_clearance(curve.evaluate(times))
