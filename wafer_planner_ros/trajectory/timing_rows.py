"""
The compiled constraint rows of the time optimisation, and their exact Jacobians.

Every constraint is an analytic function of the span durations h (the B-spline recursion
and the kinematics use plain arithmetic), so ``Im g(h + i ε e_k) / ε`` is dg/dh_k to
machine precision; a wafer sample in span s depends on h_{s-2}..h_{s+2} only, so its row
takes five complex evaluations of its own spline window (``wafer_rows``). The
control-point rows are Eq. 6-7 differentiated in closed form (``control_rows``).
"""

from numba import njit
import numpy as np

from wafer_planner_ros.geometry.kinematics import wafer_acceleration_point
from wafer_planner_ros.trajectory.bspline import DEGREE, knots_from_intervals, WINDOW
from wafer_planner_ros.trajectory.bspline import window_states

COMPLEX_STEP = 1e-30  # s: far below rounding, so Im g / step is dg/dh exactly


@njit(cache=True, nogil=True)
def wafer_rows(padded, windows, points, span, fraction, link_lengths, limits, gradients):
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
            g = wafer_g(*wafer_acceleration_point(link_lengths, state[0], state[1],
                                                  state[2]), limits)
            for c in range(parts):
                values[c, k] = g[c]
            continue
        for d in range(WINDOW - 2):  # the real parts are the values: exact to rounding
            window[:] = h
            window[d + 1] += 1j * COMPLEX_STEP
            state = window_states(window, p, fraction[k])
            g = wafer_g(*wafer_acceleration_point(link_lengths, state[0], state[1],
                                                  state[2]), limits)
            for c in range(parts):
                values[c, k] = g[c].real
                local[c, k, d] = g[c].imag / COMPLEX_STEP
    return values, local


@njit(cache=True, nogil=True)
def wafer_g(ax, ay, limits):
    """Return the x, y and |a| constraint values g = 1 - (a / limit)^2 (float or complex)."""
    norm = 1.0 + 0.0 * ax
    if limits[2] > 0.0:
        norm = 1.0 - (ax * ax + ay * ay) / (limits[2] * limits[2])
    return (1.0 - (ax / limits[0]) ** 2, 1.0 - (ay / limits[1]) ** 2, norm)


@njit(cache=True, nogil=True)
def control_rows(intervals, points, limits, gradients):
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
