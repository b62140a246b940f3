"""
An exact-sign orientation test for points given as floats, like GEOS's (and better).

``orient`` returns the sign of the turn a -> b -> c exactly: a floating-point filter with
Shewchuk's error bound decides almost every case, exact expansion arithmetic the rest, and
:class:`fractions.Fraction` the coordinates so small or large (``is_safe`` false) that the
expansions could underflow or overflow. Compiled with numba; ``orientation`` is the
Python-facing form.
"""

from fractions import Fraction

import numpy as np

from wafer_planner_ros.kernels import kernel, objmode

# Shewchuk's bound on the rounding error of the 2x2 orientation determinant (orient2d, A).
_EPS = 2.0 ** -53
_CCW_BOUND = (3.0 + 16.0 * _EPS) * _EPS
_SPLITTER = 2.0 ** 27 + 1.0
# Within these magnitudes the error-free products below can neither underflow nor overflow.
_SAFE_MIN = 2.0 ** -300
_SAFE_MAX = 2.0 ** 300


def _orient_fraction(ax, ay, bx, by, cx, cy) -> int:
    ax, ay, bx, by, cx, cy = (Fraction(v) for v in (ax, ay, bx, by, cx, cy))
    det = (ax - cx) * (by - cy) - (ay - cy) * (bx - cx)
    return (det > 0) - (det < 0)


@kernel
def _two_sum(a, b):
    s = a + b
    bv = s - a
    av = s - bv
    return s, (a - av) + (b - bv)


@kernel
def _split(a):
    c = _SPLITTER * a
    hi = c - (c - a)
    return hi, a - hi


@kernel
def _two_product(a, b):
    p = a * b
    ahi, alo = _split(a)
    bhi, blo = _split(b)
    return p, alo * blo - (((p - ahi * bhi) - alo * bhi) - ahi * blo)


@kernel
def _orient_expansion(ax, ay, bx, by, cx, cy):
    """Return the exact sign of the determinant as a sum of 16 error-free products."""
    acx, acx_t = _two_sum(ax, -cx)
    bcy, bcy_t = _two_sum(by, -cy)
    acy, acy_t = _two_sum(ay, -cy)
    bcx, bcx_t = _two_sum(bx, -cx)
    left = (acx, acx_t)
    right = (bcy, bcy_t)
    left2 = (acy, acy_t)
    right2 = (bcx, bcx_t)
    terms = np.empty(16)
    k = 0
    for u in left:
        for v in right:
            p, e = _two_product(u, v)
            terms[k] = p
            terms[k + 1] = e
            k += 2
    for u in left2:
        for v in right2:
            p, e = _two_product(u, v)
            terms[k] = -p
            terms[k + 1] = -e
            k += 2
    # Shewchuk's Grow-Expansion: the sum stays exact as non-overlapping components of
    # increasing magnitude, so the largest non-zero one carries the sign.
    expansion = np.zeros(16)
    for m in range(16):
        carry = terms[m]
        for c in range(m):
            carry, expansion[c] = _two_sum(carry, expansion[c])
        expansion[m] = carry
    for m in range(15, -1, -1):
        if expansion[m] > 0.0:
            return 1
        if expansion[m] < 0.0:
            return -1
    return 0


@kernel
def _in_range(ax, ay, bx, by, cx, cy):
    """Return whether every non-zero coordinate of the three points is in the safe range."""
    for v in (ax, ay, bx, by, cx, cy):
        size = abs(v)
        if size != 0.0 and not _SAFE_MIN <= size <= _SAFE_MAX:
            return False
    return True


@kernel
def orient(ax, ay, bx, by, cx, cy, safe):
    """
    Return the exact sign of the turn a -> b -> c (1 left, -1 right, 0 collinear).

    ``safe``: every coordinate of the polygon is known to be in the safe range (``is_safe``);
    when it is not, only a turn whose own points are outside it takes the slow exact path.
    """
    if not safe and not _in_range(ax, ay, bx, by, cx, cy):
        with objmode(sign='int64'):
            sign = _orient_fraction(ax, ay, bx, by, cx, cy)
        return sign
    left = (ax - cx) * (by - cy)
    right = (ay - cy) * (bx - cx)
    det = left - right
    # Within the safe range the rounded products keep the signs of the exact ones.
    if left > 0.0:
        if right <= 0.0:
            return 1
        total = left + right
    elif left < 0.0:
        if right >= 0.0:
            return -1
        total = -left - right
    else:
        return 1 if det > 0.0 else (-1 if det < 0.0 else 0)
    bound = _CCW_BOUND * total
    if det > bound:
        return 1
    if -det > bound:
        return -1
    return _orient_expansion(ax, ay, bx, by, cx, cy)


def orientation(a, b, c) -> int:
    """Return the exact sign of the turn a -> b -> c: 1 left (ccw), -1 right, 0 collinear."""
    safe = is_safe(np.array([a, b, c], dtype=float))
    return int(orient(float(a[0]), float(a[1]), float(b[0]), float(b[1]),
                      float(c[0]), float(c[1]), safe))


def is_safe(xy: np.ndarray) -> bool:
    """Return whether every non-zero coordinate is within the range ``orient`` computes in."""
    size = np.abs(xy[xy != 0.0])
    return not len(size) or bool(size.min() >= _SAFE_MIN and size.max() <= _SAFE_MAX)
