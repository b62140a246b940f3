"""
The compiled constraint rows of both optimisations, with exact Jacobians.

Rows are g >= 0. Control-point rows (velocity, acceleration, jerk: ``control_rows``) are
Eq. 6-7 differentiated in closed form. Sample rows (the wafer acceleration at a (span,
fraction) sample: ``wafer_rows``; the joint positions there, which clearance rows are
made of: ``position_samples``) depend on the control points
P_s..P_{s+3} and the durations h_{s-2}..h_{s+2} of the sample's span s: with
q^(r) = sum_j B^(r)_j(h) P_{s+j} (r = 0, 1, 2), dg/dP_{s+j,i} = sum_r dg/dq^(r)_i B^(r)_j
with the kinematics' partials in closed form, and
dg/dh = sum_{r,i} dg/dq^(r)_i sum_j dB^(r)_j/dh P_{s+j,i} with dB/dh by the complex step
on the basis alone: every function is analytic, so ``Im B(h + i e e_k) / e`` is exact to
rounding. ``scatter_rows`` writes sample rows into a solver's columns. The knot-time
optimisation (``timing_problem``) uses the duration columns alone; the whole-curve
optimisation (``shape_problem``) the control points' as well.
"""

import numpy as np

from wafer_planner_ros.kernels import kernel
from wafer_planner_ros.trajectory.bspline import DEGREE, knots_from_intervals, raise_degree
from wafer_planner_ros.trajectory.bspline import WINDOW

COMPLEX_STEP = 1e-30
"""Far below rounding, so Im f(h + i step) / step is df/dh exactly."""
LOCAL = WINDOW - 2
"""Durations a sample depends on: h_{s-2}..h_{s+2}."""


@kernel(nogil=True)
def control_rows(points, intervals, limit, order, point_column, duration_column, scale,
                 values_out, jacobian, row0, gradients=True):
    """
    Write the control-point rows 1 - (D / limit)^2 of one derivative and their Jacobian.

    ``order``: 1 velocity, 2 acceleration, 3 jerk; ``limit`` (3,) per joint, the margin in
    it. Rows from ``row0`` on: every control point of that derivative, joint by joint.
    Eq. 6-7 differentiated: D'_i = d (D_{i+1} - D_i) / w_i with w_i = h_{i+o-2} + ... + h_i
    for the o-th derivative points D (degree d = 3 - o), so
    dD'_i/dh_k = (d (dD_{i+1} - dD_i) - D'_i [k in w_i]) / w_i, and dD'_i/dP by the same
    recursion (per joint). Columns as in ``scatter_rows``; with every ``point_column`` -1
    (the control points fixed) only the durations are carried, and without ``gradients``
    nothing. Returns the row after the last written.
    """
    count, m = len(points), len(intervals)
    moving = gradients and point_column.max() >= 0
    knots = knots_from_intervals(intervals)
    current = points.copy()
    by_p = np.eye(count)                    # d current[i] / d P[k], the same joint
    by_h = np.zeros((count, 3, m))
    for lower in range(order):
        degree = DEGREE - lower
        n = len(current) - 1
        following = np.empty((n, 3))
        following_p = np.zeros((n, count))
        following_h = np.zeros((n, 3, m))
        for i in range(n):
            width = knots[i + 4] - knots[i + 1 + lower]
            factor = degree / width
            for j in range(3):
                following[i, j] = factor * (current[i + 1, j] - current[i, j])
            if not gradients:
                continue
            if moving:
                for k in range(count):
                    following_p[i, k] = factor * (by_p[i + 1, k] - by_p[i, k])
            for k in range(m):
                inside = i + lower - 2 <= k <= i
                for j in range(3):
                    d = degree * (by_h[i + 1, j, k] - by_h[i, j, k])
                    if inside:
                        d -= following[i, j]
                    following_h[i, j, k] = d / width
        current, by_p, by_h = following, following_p, following_h
    row = row0
    for i in range(len(current)):
        for j in range(3):
            ratio = current[i, j] / limit[j]
            values_out[row] = 1.0 - ratio * ratio
            row += 1
            if not gradients:
                continue
            coef = -2.0 * ratio / limit[j]
            for k in range(count if moving else 0):
                column = point_column[k, j]
                if column >= 0 and by_p[i, k] != 0.0:
                    jacobian[row - 1, column] = coef * by_p[i, k]
            for k in range(m):
                jacobian[row - 1, duration_column[k]] = coef * by_h[i, j, k] * scale[k]
    return row


def control_row_count(count: int, order: int) -> int:
    """Return how many rows ``control_rows`` writes of derivative ``order`` of ``count`` points."""
    return 3 * (count - order)


@kernel(nogil=True)
def basis_all(h, fraction, out):
    """
    Write B^(r)_j (3, 4) into ``out``: the r-th derivative weights of P_s..P_{s+3}.

    ``h`` (7,): the durations h_{s-3}..h_{s+3} (float or complex), as in ``window_states``,
    whose Cox-de Boor recursion and derivative points (Eq. 6-7) this follows.
    """
    knots = np.zeros(WINDOW + 1, dtype=h.dtype)
    for j in range(WINDOW):
        knots[j + 1] = knots[j] + h[j]
    t = knots[DEGREE] + h[DEGREE] * fraction
    left = np.zeros(DEGREE + 1, dtype=h.dtype)
    right = np.zeros(DEGREE + 1, dtype=h.dtype)
    funcs = np.zeros(DEGREE + 1, dtype=h.dtype)
    funcs[0] = 1.0
    first = np.zeros(2, dtype=h.dtype)    # degree 1: weights of the acceleration points
    second = np.zeros(3, dtype=h.dtype)   # degree 2: weights of the velocity points
    for j in range(1, DEGREE + 1):
        raise_degree(funcs, left, right, knots, t, j)
        if j == 1:
            first[0], first[1] = funcs[0], funcs[1]
        elif j == 2:
            second[0], second[1], second[2] = funcs[0], funcs[1], funcs[2]
    velocity = np.zeros(3, dtype=h.dtype)  # V_r = velocity[r] (P_{r+1} - P_r)
    for r in range(3):
        velocity[r] = 3.0 / (knots[r + 4] - knots[r + 1])
    for j in range(DEGREE + 1):
        out[0, j] = funcs[j]
        out[1, j] = 0.0 * h[0]
        out[2, j] = 0.0 * h[0]
    for r in range(3):
        out[1, r + 1] += second[r] * velocity[r]
        out[1, r] -= second[r] * velocity[r]
    for r in range(2):  # A_r = 2 (V_{r+1} - V_r) / (knots[r+4] - knots[r+2])
        weight = first[r] * 2.0 / (knots[r + 4] - knots[r + 2])
        out[2, r + 2] += weight * velocity[r + 1]
        out[2, r + 1] -= weight * (velocity[r + 1] + velocity[r])
        out[2, r] += weight * velocity[r]


@kernel(nogil=True)
def _kinematic_partials(link_lengths, q, qd, qdd, dax, day):
    """
    Return the wafer acceleration (ax, ay); write d ax / d q^(r)_i into dax (3, 3), day.

    ``wafer_acceleration_point`` differentiated: with th_j, w_j, a_j the cumulative angles,
    speeds and accelerations, joint i moves the links j >= i.
    """
    theta = omega = alpha = 0.0
    ax = ay = 0.0
    cos, sin = np.zeros(3), np.zeros(3)
    speed, accel = np.zeros(3), np.zeros(3)
    for j in range(3):
        theta, omega, alpha = theta + q[j], omega + qd[j], alpha + qdd[j]
        cos[j], sin[j], speed[j], accel[j] = np.cos(theta), np.sin(theta), omega, alpha
        ax -= link_lengths[j] * (alpha * sin[j] + omega * omega * cos[j])
        ay += link_lengths[j] * (alpha * cos[j] - omega * omega * sin[j])
    for i in range(3):
        qx = qy = vx = vy = accx = accy = 0.0
        for j in range(i, 3):
            length, c, s, w, a = link_lengths[j], cos[j], sin[j], speed[j], accel[j]
            qx -= length * (a * c - w * w * s)
            qy -= length * (a * s + w * w * c)
            vx -= 2.0 * length * w * c
            vy -= 2.0 * length * w * s
            accx -= length * s
            accy += length * c
        dax[0, i], dax[1, i], dax[2, i] = qx, vx, accx
        day[0, i], day[1, i], day[2, i] = qy, vy, accy
    return ax, ay


@kernel(nogil=True)
def _sample_state(h, fraction, points, s, basis, state):
    """Write the basis weights B^(r)_j (3, 4) at a sample and its state q^(r)_i (3, 3)."""
    basis_all(h, fraction, basis)
    for r in range(3):
        for i in range(3):
            total = 0.0
            for j in range(DEGREE + 1):
                total += basis[r, j] * points[s + j, i]
            state[r, i] = total


@kernel(nogil=True)
def _by_durations(h, fraction, points, s, dg, parts, k, window, stepped, moved, by_h):
    """
    Write d value / d h_{s-2..s+2} of a sample's ``parts`` values into ``by_h[:, k]``.

    ``dg`` (c, 3, 3): each value's derivative by q^(r)_i; the basis by each duration by the
    complex step (``COMPLEX_STEP``) on the basis alone.
    """
    for d in range(LOCAL):
        for e in range(WINDOW):
            window[e] = h[e]
        window[d + 1] += 1j * COMPLEX_STEP
        basis_all(window, fraction, stepped)
        for r in range(3):
            for i in range(3):
                total = 0.0
                for j in range(DEGREE + 1):
                    total += stepped[r, j].imag * points[s + j, i]
                moved[r, i] = total / COMPLEX_STEP
        for c in range(parts):
            total = 0.0
            for r in range(3):
                for i in range(3):
                    total += dg[c, r, i] * moved[r, i]
            by_h[c, k, d] = total


@kernel(nogil=True)
def wafer_rows(padded, points, span, fraction, link_lengths, limits, gradients=True):
    """
    Return the wafer rows per sample (values (c, K), d/dh (c, K, 5), d/dP (c, K, 4, 3)).

    1 - (a / limit)^2 on x and y, and on |a| too when ``limits`` (c,) holds three limits
    (x, y, |a|; two: x, y). Derivatives are by h_{s-2}..h_{s+2} and P_s..P_{s+3}; without
    ``gradients`` they stay zero. ``padded``: the durations with three zeros at each end.
    """
    count, parts = len(span), len(limits)
    values = np.empty((parts, count))
    by_h = np.zeros((parts, count, LOCAL))
    by_p = np.zeros((parts, count, DEGREE + 1, 3))
    basis = np.empty((3, DEGREE + 1))
    stepped = np.empty((3, DEGREE + 1), dtype=np.complex128)
    window = np.empty(WINDOW, dtype=np.complex128)
    state, moved = np.zeros((3, 3)), np.zeros((3, 3))
    dax, day = np.zeros((3, 3)), np.zeros((3, 3))
    dg = np.zeros((parts, 3, 3))              # d value / d q^(r)_i
    for k in range(count):
        s = span[k]
        h = padded[s:s + WINDOW]
        _sample_state(h, fraction[k], points, s, basis, state)
        ax, ay = _kinematic_partials(link_lengths, state[0], state[1], state[2], dax, day)
        values[0, k] = 1.0 - (ax / limits[0]) ** 2
        values[1, k] = 1.0 - (ay / limits[1]) ** 2
        gx, gy = -2.0 * ax / limits[0] ** 2, -2.0 * ay / limits[1] ** 2
        for r in range(3):
            for i in range(3):
                dg[0, r, i] = gx * dax[r, i]
                dg[1, r, i] = gy * day[r, i]
        if parts == 3:
            square = limits[2] * limits[2]
            values[2, k] = 1.0 - (ax * ax + ay * ay) / square
            for r in range(3):
                for i in range(3):
                    dg[2, r, i] = -2.0 * (ax * dax[r, i] + ay * day[r, i]) / square
        if not gradients:
            continue
        for c in range(parts):
            for j in range(DEGREE + 1):
                for i in range(3):
                    total = 0.0
                    for r in range(3):
                        total += dg[c, r, i] * basis[r, j]
                    by_p[c, k, j, i] = total
        _by_durations(h, fraction[k], points, s, dg, parts, k, window, stepped, moved, by_h)
    return values, by_h, by_p


@kernel(nogil=True)
def position_samples(padded, points, span, fraction, gradients=True):
    """
    Return the joint positions per sample (q (3, K), d/dh (3, K, 5), weights (3, K, 4, 3)).

    As ``wafer_rows``, of q itself; the third array holds the basis weight of P_{s+j} in
    column 0 (dq_i / dP_{s+j,i}, the same for every joint).
    """
    count = len(span)
    values = np.empty((3, count))
    by_h = np.zeros((3, count, LOCAL))
    by_p = np.zeros((3, count, DEGREE + 1, 3))
    basis = np.empty((3, DEGREE + 1))
    stepped = np.empty((3, DEGREE + 1), dtype=np.complex128)
    window = np.empty(WINDOW, dtype=np.complex128)
    state, moved = np.zeros((3, 3)), np.zeros((3, 3))
    dg = np.zeros((3, 3, 3))                  # d q_c / d q^(r)_i
    for k in range(count):
        s = span[k]
        h = padded[s:s + WINDOW]
        _sample_state(h, fraction[k], points, s, basis, state)
        for i in range(3):
            values[i, k] = state[0, i]
        if not gradients:
            continue
        dg[:] = 0.0
        for i in range(3):
            dg[i, 0, i] = 1.0
            for j in range(DEGREE + 1):
                by_p[i, k, j, 0] = basis[0, j]
        _by_durations(h, fraction[k], points, s, dg, 3, k, window, stepped, moved, by_h)
    return values, by_h, by_p


@kernel(nogil=True)
def scatter_rows(jacobian, values_out, row0, values, by_h, by_p, span, point_column,
                 duration_column, scale):
    """
    Write rows (c, K) from ``row0`` on: values, and their Jacobian by the solver's columns.

    ``point_column`` (count, 3): each control-point coordinate's column, -1 when fixed;
    ``duration_column`` (m,); durations are variables relative to ``scale``.
    """
    parts, count = values.shape
    spans = len(duration_column)
    for c in range(parts):
        for k in range(count):
            row = row0 + c * count + k
            values_out[row] = values[c, k]
            s = span[k]
            for d in range(LOCAL):
                j = s - 2 + d
                if 0 <= j < spans:
                    jacobian[row, duration_column[j]] = by_h[c, k, d] * scale[j]
            for j in range(DEGREE + 1):
                for i in range(3):
                    column = point_column[s + j, i]
                    if column >= 0:
                        jacobian[row, column] = by_p[c, k, j, i]
