"""
The compiled rows of the whole-curve optimisation: values and exact Jacobians.

A point of span s depends on the control points P_s..P_{s+3} and the durations
h_{s-2}..h_{s+2} (``bspline.window_states``). Every row here is an analytic function of
both, so the complex step gives exact derivatives: by each of the five durations and, for
the wafer rows, by each of the twelve control-point coordinates. Positions are linear in
the control points: their weights are the basis functions, evaluated by the same recursion
on unit control points. Control-point rows (velocity, acceleration, jerk) are linear in P
for given durations: ``derivative_matrices`` gives the matrices.
"""

from numba import njit
import numpy as np

from wafer_planner_ros.geometry.kinematics import wafer_acceleration_point
from wafer_planner_ros.trajectory.bspline import DEGREE, derivative_points, WINDOW
from wafer_planner_ros.trajectory.bspline import window_states
from wafer_planner_ros.trajectory.timing_rows import COMPLEX_STEP, wafer_g

LOCAL = WINDOW - 2
"""Durations a sample depends on: h_{s-2}..h_{s+2}."""


@njit(cache=True, nogil=True)
def wafer_rows_full(padded, windows, points, span, fraction, link_lengths, limits):
    """
    Return the wafer constraints (c, K), d/dh (c, K, 5) and d/dP (c, K, 4, 3).

    ``limits``: x, y, |a| limits with the margin (|a| absent when 0). The derivatives are by
    h_{s-2}..h_{s+2} and by P_s..P_{s+3} of each sample's span s.
    """
    parts = 3 if limits[2] > 0.0 else 2
    values = np.empty((parts, len(span)))
    by_h = np.zeros((parts, len(span), LOCAL))
    by_p = np.zeros((parts, len(span), DEGREE + 1, 3))
    window = np.empty(WINDOW, dtype=np.complex128)
    local = np.empty((DEGREE + 1, 3), dtype=np.complex128)
    for k in range(len(span)):
        h = padded[windows[k]]
        p = points[span[k]:span[k] + DEGREE + 1]
        for d in range(LOCAL + 3 * (DEGREE + 1)):
            window[:] = h
            local[:] = p
            if d < LOCAL:
                window[d + 1] += 1j * COMPLEX_STEP
            else:
                local[(d - LOCAL) // 3, (d - LOCAL) % 3] += 1j * COMPLEX_STEP
            state = window_states(window, local, fraction[k])
            g = wafer_g(*wafer_acceleration_point(link_lengths, state[0], state[1],
                                                  state[2]), limits)
            for c in range(parts):
                values[c, k] = g[c].real
                if d < LOCAL:
                    by_h[c, k, d] = g[c].imag / COMPLEX_STEP
                else:
                    by_p[c, k, (d - LOCAL) // 3, (d - LOCAL) % 3] = g[c].imag / COMPLEX_STEP
    return values, by_h, by_p


@njit(cache=True, nogil=True)
def position_rows(padded, windows, points, span, fraction):
    """
    Return q (K, 3), dq/dh (K, 5, 3) and the basis weights (K, 4) at the samples.

    q = sum_j basis[j] P_{s+j}; the weights do not depend on P.
    """
    q = np.empty((len(span), 3))
    by_h = np.zeros((len(span), LOCAL, 3))
    basis = np.empty((len(span), DEGREE + 1))
    window = np.empty(WINDOW, dtype=np.complex128)
    unit = np.zeros((DEGREE + 1, 3))
    for k in range(len(span)):
        h = padded[windows[k]]
        p = points[span[k]:span[k] + DEGREE + 1]
        for d in range(LOCAL):
            window[:] = h
            window[d + 1] += 1j * COMPLEX_STEP
            state = window_states(window, p.astype(np.complex128), fraction[k])
            for i in range(3):
                q[k, i] = state[0, i].real
                by_h[k, d, i] = state[0, i].imag / COMPLEX_STEP
        for j in range(DEGREE + 1):
            unit[:] = 0.0
            unit[j] = 1.0
            basis[k, j] = window_states(h, unit, fraction[k])[0, 0]
    return q, by_h, basis


def derivative_matrices(knots: np.ndarray, count: int, orders: int) -> list:
    """
    Return [M_1, M_2 (, M_3)] with D^(o) = M_o P: the derivatives' control points.

    M_o (count - o, count) gives those of the o-th derivative (velocity, acceleration,
    jerk). ``count``: control points; ``orders``: 2 (velocity, acceleration) or 3 (and jerk).
    """
    matrix = np.eye(count)
    out = []
    for order in range(orders):
        matrix = derivative_points(matrix, knots[order:len(knots) - order], DEGREE - order)
        out.append(matrix)
    return out
