"""
Simple polygons from user-written points: validated exactly as GEOS validates a polygon shell.

:func:`simple_polygon` drops what GEOS also ignores (the last point when it repeats the first,
and a vertex that repeats the one before it), keeps every other vertex as written (collinear
ones included) and refuses the polygon when fewer than 3 distinct points remain, when it has
zero area, or when two edges intersect anywhere other than at the vertex that adjacent edges
share: a crossing, a vertex on another edge, a vertex passed twice, a collinear overlap or a
spike (an edge doubling back over its neighbour). Edge ``k`` runs from point ``k`` to point
``k + 1`` of the points as written (the last one back to point 0), so a reason can be found
in the file.

The orientation test is exact in sign, like GEOS's (``predicates``). Candidate edge pairs
come from a sort-and-sweep over the edges' x-extents, compiled with numba. Polygons of up
to ``INTERPRETED_VERTICES`` vertices are checked by the same kernels run as Python while
numba is not loaded yet (``kernels``): so the node reads its cell file without numba.
"""

from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from wafer_planner_ros import kernels
from wafer_planner_ros.geometry.predicates import is_safe, orient, orientation
from wafer_planner_ros.kernels import kernel

_NONE, _CROSS, _TOUCH, _OVERLAP = 0, 1, 2, 3
INTERPRETED_VERTICES = 64
"""Up to this many vertices in all, a check runs interpreted until numba is loaded."""


class PolygonError(ValueError):
    """A polygon that is not simple; the message is the reason."""

    def __init__(self, reason: str):
        """Keep the reason (also the message)."""
        super().__init__(reason)
        self.reason = reason


@dataclass(frozen=True, eq=False)
class SimplePolygon:
    """A validated simple polygon."""

    points: np.ndarray
    """(V, 2) vertices (m), counter-clockwise, without repeated or closing points."""
    notes: tuple = ()
    """What was dropped from the points as written, one sentence each."""


def simple_polygon(points, form=None) -> SimplePolygon:
    """
    Return the points as a validated, counter-clockwise :class:`SimplePolygon`.

    Raise :class:`PolygonError` naming the two edges and where they meet when the polygon is
    not a valid GEOS shell. ``form``: how the kernels run (``kernels.sized``), by default
    interpreted up to ``INTERPRETED_VERTICES`` vertices until numba is loaded.
    """
    xy = np.array(points, dtype=float)
    if xy.ndim != 2 or xy.shape[1] != 2:
        raise PolygonError('must be a list of [x, y] points')
    bad = np.flatnonzero(~np.isfinite(xy).all(axis=1))
    if len(bad):
        raise PolygonError(f'point {bad[0]} is not finite')
    end, notes = _drop_closing(xy)
    keep = np.ones(end, dtype=bool)
    keep[1:] = np.any(xy[1:end] != xy[:end - 1], axis=1)
    notes += _repeat_notes(keep)
    kept = np.flatnonzero(keep)
    vertices = np.ascontiguousarray(xy[kept])
    if len(np.unique(vertices + 0.0, axis=0)) < 3:  # + 0.0: -0.0 is the same point as 0.0
        raise PolygonError('has fewer than 3 distinct points')
    safe = is_safe(vertices)
    form = form or kernels.sized(len(vertices), INTERPRETED_VERTICES)
    if form(_all_collinear)(vertices, safe):
        raise PolygonError('has zero area (all its points lie on one line)')
    i, j, kind = form(_first_intersection)(vertices, safe)
    if kind != _NONE:
        # Edge k of the vertices starts at the last written copy of vertex k.
        labels = np.append(kept[1:] - 1, end - 1)
        raise PolygonError(_describe(vertices, i, j, kind, labels, safe))
    if not form(_counter_clockwise)(vertices, safe):
        vertices = vertices[::-1].copy()
    return SimplePolygon(points=vertices, notes=tuple(notes))


def touches_or_overlaps(a, b, form=None) -> bool:
    """
    Return whether the closed regions of polygons ``a`` and ``b`` share at least one point.

    True when an edge of one touches, crosses or overlaps an edge of the other, or one lies
    inside the other; exact, like :func:`simple_polygon` (``form`` as there).
    """
    a = np.ascontiguousarray(a, dtype=float)
    b = np.ascontiguousarray(b, dtype=float)
    safe = is_safe(a) and is_safe(b)
    form = form or kernels.sized(len(a) + len(b), INTERPRETED_VERTICES)
    if form(_edges_meet)(a, b, safe):
        return True
    # No edges meet, so each vertex is strictly inside or strictly outside the other polygon.
    inside = form(_inside)
    return bool(inside(a[0, 0], a[0, 1], b, safe) or inside(b[0, 0], b[0, 1], a, safe))


def _drop_closing(xy: np.ndarray) -> tuple:
    end = len(xy)
    while end > 1 and np.all(xy[end - 1] == xy[0]):
        end -= 1
    dropped = len(xy) - end
    if dropped == 0:
        return end, []
    if dropped == 1:
        return end, ['the last point repeats the first (a closed ring) and was dropped']
    return end, [f'the last {dropped} points repeat the first (a closed ring) and were dropped']


def _repeat_notes(keep: np.ndarray) -> list:
    notes = []
    dropped = np.flatnonzero(~keep)
    if not len(dropped):
        return notes
    runs = np.split(dropped, np.flatnonzero(np.diff(dropped) > 1) + 1)
    for run in runs:
        first, last = int(run[0]), int(run[-1])
        if first == last:
            notes.append(f'vertex {first} repeats vertex {first - 1} and was dropped')
        else:
            notes.append(f'vertices {first} to {last} repeat vertex {first - 1} and were '
                         f'dropped')
    return notes


def _describe(xy, i, j, kind, labels, safe) -> str:
    n = len(xy)
    p, q = xy[i], xy[(i + 1) % n]
    r, s = xy[j], xy[(j + 1) % n]
    edges = f'edges {labels[i]} and {labels[j]}'
    if kind == _OVERLAP:
        axis = 0 if p[0] != q[0] else 1
        ends = sorted([p, q, r, s], key=lambda v: v[axis])
        spike = ''
        if (i + 1) % n == j or (j + 1) % n == i:
            tip = labels[j] if (i + 1) % n == j else labels[i]
            spike = f' (a spike at vertex {tip})'
        return (f'self-intersecting: {edges} overlap along a stretch from {_point(ends[1])} '
                f'to {_point(ends[2])}{spike}')
    if kind == _TOUCH:
        for v in (p, q):
            if any(np.all(v == w) for w in (r, s)):
                return f'self-intersecting: {edges} meet at {_point(v)}'
        for v, (u, w) in ((p, (r, s)), (q, (r, s)), (r, (p, q)), (s, (p, q))):
            if orientation(u, w, v) == 0:
                return f'self-intersecting: {edges} meet at {_point(v)}'
    # A proper crossing, computed in fractions: nearly parallel edges can round to parallel.
    (px, py), (qx, qy), (rx, ry), (sx, sy) = (
        (Fraction(x), Fraction(y)) for x, y in (p, q, r, s))
    t = ((rx - px) * (sy - ry) - (ry - py) * (sx - rx)) / (
        (qx - px) * (sy - ry) - (qy - py) * (sx - rx))
    at = (px + t * (qx - px), py + t * (qy - py))
    return f'self-intersecting: {edges} cross at {_point(at)}'


def _point(v) -> str:
    return f'({_number(v[0])}, {_number(v[1])})'


def _number(x: float) -> str:
    x = float(x)
    if x == 0.0 or 1e-2 <= abs(x) < 1e5:
        return f'{x:.3f}'
    return f'{x:.3g}'  # below a centimetre 3 decimals say too little


@kernel
def _same_direction(ux, uy, vx, vy):
    """Return whether collinear vectors u and v (both non-zero) point the same way."""
    return (ux > 0.0) == (vx > 0.0) and (ux < 0.0) == (vx < 0.0) and \
        (uy > 0.0) == (vy > 0.0) and (uy < 0.0) == (vy < 0.0)


@kernel
def _segments(px, py, qx, qy, rx, ry, sx, sy, safe):
    """Return how segments p-q and r-s with overlapping bounding boxes intersect."""
    o1 = orient(px, py, qx, qy, rx, ry, safe)
    o2 = orient(px, py, qx, qy, sx, sy, safe)
    if o1 * o2 > 0:
        return _NONE
    o3 = orient(rx, ry, sx, sy, px, py, safe)
    o4 = orient(rx, ry, sx, sy, qx, qy, safe)
    if o3 * o4 > 0:
        return _NONE
    if o1 == 0 and o2 == 0 and o3 == 0 and o4 == 0:
        if px != qx or rx != sx:
            lo = max(min(px, qx), min(rx, sx))
            hi = min(max(px, qx), max(rx, sx))
        else:
            lo = max(min(py, qy), min(ry, sy))
            hi = min(max(py, qy), max(ry, sy))
        if lo < hi:
            return _OVERLAP
        return _TOUCH if lo == hi else _NONE
    if o1 == 0 or o2 == 0 or o3 == 0 or o4 == 0:
        return _TOUCH
    return _CROSS


@kernel
def _pair(xy, i, j, safe):
    """Return how edges i and j of the ring xy intersect beyond a shared vertex."""
    n = xy.shape[0]
    if (i + 1) % n == j or (j + 1) % n == i:
        first, second = (i, j) if (i + 1) % n == j else (j, i)
        p = xy[first]
        q = xy[second]
        r = xy[(second + 1) % n]
        # Adjacent edges meet at q; beyond it only when the second doubles back (a spike).
        if orient(p[0], p[1], q[0], q[1], r[0], r[1], safe) == 0 and _same_direction(
                p[0] - q[0], p[1] - q[1], r[0] - q[0], r[1] - q[1]):
            return _OVERLAP
        return _NONE
    p = xy[i]
    q = xy[(i + 1) % n]
    r = xy[j]
    s = xy[(j + 1) % n]
    return _segments(p[0], p[1], q[0], q[1], r[0], r[1], s[0], s[1], safe)


@kernel
def _boxes(starts, ends):
    lo = np.minimum(starts, ends)
    hi = np.maximum(starts, ends)
    return lo[:, 0].copy(), hi[:, 0].copy(), lo[:, 1].copy(), hi[:, 1].copy()


@kernel
def _first_intersection(xy, safe):
    """
    Return (i, j, kind) of the intersecting edge pair with the smallest (i, j), i < j.

    kind is 0 (and i, j are -1) for a simple ring. Edges are swept in order of their
    smallest x; a pair is tested only when the bounding boxes overlap.
    """
    n = xy.shape[0]
    ends = np.empty_like(xy)
    ends[:n - 1] = xy[1:]
    ends[n - 1] = xy[0]
    x_lo, x_hi, y_lo, y_hi = _boxes(xy, ends)
    order = np.argsort(x_lo, kind='mergesort')
    # In sweep order, so that the inner loop reads memory in sequence.
    x_lo, x_hi, y_lo, y_hi = x_lo[order], x_hi[order], y_lo[order], y_hi[order]
    best_i, best_j, best_kind = -1, -1, 0
    for a in range(n):
        i = order[a]
        for b in range(a + 1, n):
            if x_lo[b] > x_hi[a]:
                break
            if y_lo[b] > y_hi[a] or y_lo[a] > y_hi[b]:
                continue
            j = order[b]
            lo, hi = min(i, j), max(i, j)
            if best_i >= 0 and (lo > best_i or (lo == best_i and hi >= best_j)):
                continue
            kind = _pair(xy, lo, hi, safe)
            if kind != _NONE:
                best_i, best_j, best_kind = lo, hi, kind
    return best_i, best_j, best_kind


@kernel
def _all_collinear(xy, safe):
    """Return whether every vertex lies on the line through the first two distinct ones."""
    n = xy.shape[0]
    ax, ay = xy[0, 0], xy[0, 1]
    k = 1
    while k < n and xy[k, 0] == ax and xy[k, 1] == ay:
        k += 1
    if k == n:
        return True
    bx, by = xy[k, 0], xy[k, 1]
    for m in range(k + 1, n):
        if orient(ax, ay, bx, by, xy[m, 0], xy[m, 1], safe) != 0:
            return False
    return True


@kernel
def _counter_clockwise(xy, safe):
    """Return whether a simple ring runs counter-clockwise (the turn at its lowest vertex)."""
    n = xy.shape[0]
    k = 0
    for m in range(1, n):
        if xy[m, 1] < xy[k, 1] or (xy[m, 1] == xy[k, 1] and xy[m, 0] < xy[k, 0]):
            k = m
    p = xy[(k - 1) % n]
    q = xy[k]
    r = xy[(k + 1) % n]
    return orient(p[0], p[1], q[0], q[1], r[0], r[1], safe) > 0


@kernel
def _edges_meet(a, b, safe):
    """Return whether an edge of ring a touches, crosses or overlaps an edge of ring b."""
    na, nb = a.shape[0], b.shape[0]
    xy = np.concatenate((a, b))
    ends = np.empty_like(xy)
    ends[:na - 1] = a[1:]
    ends[na - 1] = a[0]
    ends[na:na + nb - 1] = b[1:]
    ends[na + nb - 1] = b[0]
    x_lo, x_hi, y_lo, y_hi = _boxes(xy, ends)
    order = np.argsort(x_lo, kind='mergesort')
    x_lo, x_hi, y_lo, y_hi = x_lo[order], x_hi[order], y_lo[order], y_hi[order]
    for c in range(na + nb):
        i = order[c]
        for d in range(c + 1, na + nb):
            if x_lo[d] > x_hi[c]:
                break
            j = order[d]
            if (i < na) == (j < na) or y_lo[d] > y_hi[c] or y_lo[c] > y_hi[d]:
                continue
            if _segments(xy[i, 0], xy[i, 1], ends[i, 0], ends[i, 1],
                         xy[j, 0], xy[j, 1], ends[j, 0], ends[j, 1], safe) != _NONE:
                return True
    return False


@kernel
def _inside(px, py, ring, safe):
    """Return whether p, on no edge of the ring, is inside it (crossings to its right)."""
    n = ring.shape[0]
    inside = False
    for k in range(n):
        ux, uy = ring[k, 0], ring[k, 1]
        vx, vy = ring[(k + 1) % n, 0], ring[(k + 1) % n, 1]
        if (uy > py) != (vy > py):
            turn = orient(ux, uy, vx, vy, px, py, safe)
            if (turn > 0) == (vy > uy):
                inside = not inside
    return inside
