"""
Polygon validity compared with GEOS (shapely ``is_valid``), the reasons and the notes.

Every generated polygon is checked against ``shapely.Polygon(points).is_valid`` (a polygon
shapely refuses to build counts as invalid). The families are drawn on small integer or
dyadic grids so that exact degeneracies (collinear edges, vertices on edges, repeated
vertices) are common, then varied: scaled to metres, rotated, reversed, started elsewhere,
written as a closed ring, with repeated vertices. Where GEOS's double-double orientation
rounds (a vertex 2**-106 off a line taken as on it, or the reverse) exact arithmetic decides,
and such a polygon is listed in ``GEOS_ROUNDED`` and reported by the count test, which
requires none in the derandomised families; ``test_geos_rounding_is_where_we_differ`` shows
three found at random.
"""

from fractions import Fraction
import math
import re

from hypothesis import given, HealthCheck, settings, strategies as st
import numpy as np
import pytest
import shapely
from shapely.validation import explain_validity
from wafer_planner_ros.geometry.polygons import PolygonError, simple_polygon
from wafer_planner_ros.geometry.polygons import touches_or_overlaps
from wafer_planner_ros.geometry.predicates import orientation

COMPARED = {}
"""Polygons compared with GEOS, per family test."""
GEOS_ROUNDED = []
"""Polygons GEOS gets wrong: its double-double orientation rounds, exact arithmetic is ours."""

FAMILIES = ('grid', 'rectilinear', 'star', 'chamfer', 'sliver', 'detour')
COMPILED, INTERPRETED = (lambda k: k), (lambda k: k.interpreted)
"""How simple_polygon runs its kernels (``kernels.sized``)."""


def _settings(examples):
    return settings(max_examples=examples, deadline=None, derandomize=True, database=None,
                    suppress_health_check=[HealthCheck.too_slow])


def geos_valid(points: np.ndarray) -> bool:
    """Return shapely's verdict; a polygon shapely cannot build is invalid."""
    try:
        return bool(shapely.Polygon(points).is_valid)
    except (ValueError, shapely.errors.GEOSException):
        return False


def normalised(points: np.ndarray) -> np.ndarray:
    """Return the points without a closing copy of the first and without repeats (a loop)."""
    end = len(points)
    while end > 1 and tuple(points[end - 1]) == tuple(points[0]):
        end -= 1
    kept = [points[0]]
    for p in points[1:end]:
        if tuple(p) != tuple(kept[-1]):
            kept.append(p)
    return np.array(kept)


def _det(a, b, c) -> Fraction:
    return (a[0] - c[0]) * (b[1] - c[1]) - (a[1] - c[1]) * (b[0] - c[0])


def exact_valid(points: np.ndarray) -> bool:
    """Return GEOS's verdict computed with fractions: the reference when GEOS rounds."""
    kept = normalised(points)
    if len({(x + 0.0, y + 0.0) for x, y in kept}) < 3:
        return False
    ring = [(Fraction(x), Fraction(y)) for x, y in kept]
    n = len(ring)
    for i in range(n):
        p, q = ring[i], ring[(i + 1) % n]
        for j in range(i + 1, n):
            r, s = ring[j], ring[(j + 1) % n]
            if j == i + 1 or (i == 0 and j == n - 1):  # adjacent: only a spike is wrong
                a, b, c = (p, q, s) if j == i + 1 else (r, s, q)
                if _det(a, b, c) == 0 and (a[0] - b[0]) * (c[0] - b[0]) + (
                        a[1] - b[1]) * (c[1] - b[1]) > 0:
                    return False
                continue
            d1, d2, d3, d4 = _det(p, q, r), _det(p, q, s), _det(r, s, p), _det(r, s, q)
            if d1 * d2 > 0 or d3 * d4 > 0:
                continue
            apart = any(max(min(p[k], q[k]), min(r[k], s[k])) > min(max(p[k], q[k]),
                                                                    max(r[k], s[k]))
                        for k in (0, 1))
            if d1 == d2 == d3 == d4 == 0 and apart:  # collinear, on one line but apart
                continue
            return False
    return True


def _geos_orientation(p, q, r) -> int:
    """Return GEOS's Orientation::index(p, q, r): its filter, then double-double arithmetic."""
    detleft = (p[0] - r[0]) * (q[1] - r[1])
    detright = (p[1] - r[1]) * (q[0] - r[0])
    det = detleft - detright
    if detleft == 0.0 or (detleft > 0.0) != (detright > 0.0) or detright == 0.0:
        return (det > 0) - (det < 0)
    if abs(det) >= 1e-15 * abs(detleft + detright):
        return (det > 0) - (det < 0)
    dx1, dy1 = _dd_add((q[0], 0.0), (-p[0], 0.0)), _dd_add((q[1], 0.0), (-p[1], 0.0))
    dx2, dy2 = _dd_add((r[0], 0.0), (-q[0], 0.0)), _dd_add((r[1], 0.0), (-q[1], 0.0))
    right = _dd_mul(dy1, dx2)
    hi, lo = _dd_add(_dd_mul(dx1, dy2), (-right[0], -right[1]))
    return (hi > 0 or (hi == 0 and lo > 0)) - (hi < 0 or (hi == 0 and lo < 0))


def _dd_add(x, y):
    """Return x + y as GEOS's DD::selfAdd computes it."""
    S, T = x[0] + y[0], x[1] + y[1]
    e, f = S - x[0], T - x[1]
    s, t = S - e, T - f
    s, t = (y[0] - e) + (x[0] - s), (y[1] - f) + (x[1] - t)
    e = s + T
    H = S + e
    h = e + (S - H)
    e = t + h
    hi = H + e
    return hi, e + (H - hi)


def _dd_mul(x, y):
    """Return x * y as GEOS's DD::selfMultiply computes it."""
    split = 134217729.0
    C = split * x[0]
    hx = C - x[0]
    c = split * y[0]
    hx = C - hx
    tx = x[0] - hx
    hy = c - y[0]
    C = x[0] * y[0]
    hy = c - hy
    ty = y[0] - hy
    c = ((((hx * hy - C) + hx * ty) + tx * hy) + tx * ty) + (x[0] * y[1] + x[1] * y[0])
    hi = C + c
    return hi, c + (C - hi)


def rounds_in_geos(points: np.ndarray) -> bool:
    """Return whether GEOS's orientation of some three vertices differs from the exact one."""
    ring = normalised(points).tolist()
    for a in ring:
        for b in ring:
            for c in ring:
                exact = _det(*((Fraction(x), Fraction(y)) for x, y in (a, b, c)))
                if _geos_orientation(a, b, c) != (exact > 0) - (exact < 0):
                    return True
    return False


def on_segment(point, a, b, tolerance) -> bool:
    """Return whether the point is within tolerance of segment a-b."""
    ab = b - a
    s = np.clip(np.dot(point - a, ab) / max(np.dot(ab, ab), 1e-300), 0.0, 1.0)
    return float(np.hypot(*(a + s * ab - point))) <= tolerance


_NUMBER = r'(-?[0-9.e+-]+)'
_POINT = rf'\({_NUMBER}, {_NUMBER}\)'
_REASON = re.compile(rf'self-intersecting: edges (\d+) and (\d+) '
                     rf'(?:meet at|cross at|overlap along a stretch from) {_POINT}'
                     rf'(?: to {_POINT})?')


def checked(points, form=COMPILED):
    """Return (the polygon or None, the reason or None) as simple_polygon gives them."""
    try:
        return simple_polygon(points, form), None
    except PolygonError as error:
        return None, error.reason


def compare(family: str, points) -> None:
    """
    Assert that simple_polygon agrees with GEOS on the points, and check what it says.

    Its kernels run interpreted (as the node reads its cell file) give the same answer.
    """
    points = np.asarray(points, dtype=float)
    geos = geos_valid(points)
    polygon, reason = checked(points)
    again, again_reason = checked(points, INTERPRETED)
    assert again_reason == reason, points.tolist()
    assert polygon is None or np.array_equal(again.points, polygon.points), points.tolist()
    COMPARED[family] = COMPARED.get(family, 0) + 1
    if (polygon is not None) != geos and exact_valid(points) == (polygon is not None) \
            and rounds_in_geos(points):
        GEOS_ROUNDED.append(points)  # GEOS is wrong here: exact arithmetic agrees with us
    else:
        assert (polygon is not None) == geos, (
            f'GEOS says {explain_validity(shapely.Polygon(points)) if geos else "invalid"}, '
            f'we say {reason or "valid"}: {points.tolist()}')
    if polygon is not None:
        expected = normalised(points)
        assert shapely.Polygon(polygon.points).exterior.is_ccw
        assert (np.array_equal(polygon.points, expected)
                or np.array_equal(polygon.points, expected[::-1]))
        dropped = sum(int(n.split()[2]) if n.startswith('the last ') and 'points' in n
                      else 1 + _span(n) for n in polygon.notes)
        assert dropped == len(points) - len(expected)
        return
    if reason.startswith(('has zero area', 'has fewer than 3 distinct points')):
        return
    match = _REASON.fullmatch(reason.split(' (a spike')[0])
    assert match, reason
    i, j = int(match[1]), int(match[2])
    assert i < j < len(points), reason
    scale = float(np.abs(points).max())
    tolerance = 8e-4 + 1e-3 * scale  # the message rounds to 3 decimals or 3 digits
    for edge in (i, j):
        a, b = points[edge], points[(edge + 1) % len(points)]
        assert not np.array_equal(a, b), f'{reason}: edge {edge} has zero length'
        for k in (3, 5):
            if match[k] is not None:
                point = np.array([float(match[k]), float(match[k + 1])])
                assert on_segment(point, a, b, tolerance), f'{reason}: not on edge {edge}'


def _span(note: str) -> int:
    """Return how many more than one vertex a 'vertices a to b' note drops."""
    found = re.match(r'vertices (\d+) to (\d+) ', note)
    return int(found[2]) - int(found[1]) if found else 0


@st.composite
def variant(draw, points, scales=(1.0, 0.05, 0.25, 0.1, 0.001)):
    """Draw the points scaled, rotated, reflected, restarted, repeated and/or closed."""
    points = np.array(points, dtype=float)
    turns = draw(st.integers(0, 3))
    for _ in range(turns):
        points = np.column_stack([-points[:, 1], points[:, 0]])
    if draw(st.booleans()):
        points = points[::-1]
    points = np.roll(points, draw(st.integers(0, len(points) - 1)), axis=0)
    points = points * draw(st.sampled_from(scales))
    if draw(st.integers(0, 4)) == 0:
        points = points + np.array([0.3, -0.7])
    for _ in range(draw(st.sampled_from([0, 0, 0, 1, 2]))):
        k = draw(st.integers(0, len(points) - 1))
        points = np.insert(points, k, points[k], axis=0)
    if draw(st.booleans()):
        points = np.vstack([points, points[:1]])
    return points


@st.composite
def grid_polygons(draw):
    """Draw 3 to 9 points on a 5 x 5 grid: every kind of touching, crossing and overlap."""
    n = draw(st.integers(3, 9))
    size = draw(st.sampled_from([3, 5, 5, 7]))
    points = draw(st.lists(st.tuples(st.integers(0, size - 1), st.integers(0, size - 1)),
                           min_size=n, max_size=n))
    return draw(variant(points))


@st.composite
def rectilinear_polygons(draw):
    """Draw a band whose top and bottom are step profiles: notches, alcoves, collinear edges."""
    width = draw(st.integers(2, 9))
    cuts = st.lists(st.integers(1, width - 1), max_size=5).map(sorted)
    bottom_cuts, top_cuts = draw(cuts), draw(cuts)
    bottom = draw(st.lists(st.integers(-1, 2), min_size=len(bottom_cuts) + 1,
                           max_size=len(bottom_cuts) + 1))
    top = draw(st.lists(st.integers(1, 4), min_size=len(top_cuts) + 1,
                        max_size=len(top_cuts) + 1))
    points = []
    xs = [0] + bottom_cuts + [width]
    for k, height in enumerate(bottom):  # left to right along the bottom
        points += [(xs[k], height), (xs[k + 1], height)]
    xs = [0] + top_cuts + [width]
    for k in reversed(range(len(top))):  # right to left along the top
        points += [(xs[k + 1], top[k]), (xs[k], top[k])]
    return draw(variant(points))


@st.composite
def star_polygons(draw):
    """Draw stars: sorted or stepped directions, radii on a coarse grid, rounded to halves."""
    directions = draw(st.sampled_from([8, 12, 16, 24]))
    if draw(st.booleans()):
        n = draw(st.integers(3, 12))
        angles = sorted(draw(st.lists(st.integers(0, directions - 1), min_size=n,
                                      max_size=n)))
    else:  # a star polygon {n/k}, which crosses itself for k > 1
        n = draw(st.integers(3, 9))
        step = draw(st.integers(1, 4))
        angles = [(k * step * directions // n) % directions for k in range(n)]
    radii = draw(st.lists(st.sampled_from([0, 1, 2, 3, 4, 4, 6]), min_size=len(angles),
                          max_size=len(angles)))
    rounding = draw(st.sampled_from([1, 2, 8]))
    points = [(round(r * math.cos(2 * math.pi * a / directions) * rounding) / rounding,
               round(r * math.sin(2 * math.pi * a / directions) * rounding) / rounding)
              for a, r in zip(angles, radii)]
    return draw(variant(points))


@st.composite
def chamfered_polygons(draw):
    """Draw rectangles with each corner cut (0 cuts nothing; large cuts meet or cross)."""
    w, h = draw(st.integers(1, 6)), draw(st.integers(1, 6))
    corners = [(0, 0), (w, 0), (w, h), (0, h)]
    points = []
    for k, (x, y) in enumerate(corners):
        cut = draw(st.integers(0, 4)) / draw(st.sampled_from([1, 2]))
        inward = draw(st.integers(0, 3)) == 0
        before = np.array(corners[k - 1], float) - (x, y)
        after = np.array(corners[(k + 1) % 4], float) - (x, y)
        before, after = before / np.hypot(*before), after / np.hypot(*after)
        corner = np.array([x, y], float)
        if inward:  # a square notch in the corner instead of a chamfer
            points += [corner + cut * before, corner + cut * (before + after),
                       corner + cut * after]
        else:
            points += [corner + cut * before, corner + cut * after]
    return draw(variant([tuple(p) for p in points]))


@st.composite
def sliver_polygons(draw):
    """Draw near-degenerate polygons: a vertex within a few ulps of an edge or a line."""
    kind = draw(st.integers(0, 2))
    offset = draw(st.sampled_from([0.0, 0.0, 2.0 ** -52, -2.0 ** -52, 1e-17, -1e-17, 1e-15,
                                   -1e-12, 1e-9]))
    base = draw(st.sampled_from([0.1, 0.3, 0.7, 1.0, 1.1, 3.0]))
    t = draw(st.sampled_from([0.5, 0.25, 0.1, 1 / 3, 0.7, 0.9]))
    a = np.array([0.0, 0.0]) + base * draw(st.sampled_from([0.0, 0.1, 0.3]))
    b = a + base * np.array(draw(st.sampled_from([(1.0, 0.0), (1.0, 1.0), (0.3, 0.7),
                                                  (0.1, 0.2)])))
    on = a + t * (b - a)  # on the line a-b, up to rounding
    normal = np.array([-(b - a)[1], (b - a)[0]])
    near = on + offset * normal
    far = a + 2 * normal
    if kind == 0:  # a sliver triangle (or quadrilateral with a near-collinear vertex)
        points = [a, near, b] if draw(st.booleans()) else [a, near, b, far]
    elif kind == 1:  # a vertex pulled onto (or just off) the edge a-b from the far side
        points = [a, b, b + normal, on - offset * normal, far]
    else:  # a spike or a notch whose tip is near the previous edge
        back = a + draw(st.sampled_from([-0.5, 0.5, 1.5])) * (b - a) + offset * normal
        points = [a, b, back, far]
    return draw(variant([tuple(p) for p in points], scales=(1.0, 0.05, 3.0)))


@st.composite
def detour_polygons(draw):
    """Draw a convex polygon with a detour: a spike, a return to a vertex, or a bow-tie."""
    shape = draw(st.sampled_from([
        [(0, 0), (4, 0), (4, 4), (0, 4)], [(0, 0), (4, 0), (2, 3)],
        [(0, 0), (3, 0), (4, 2), (2, 4), (-1, 2)]]))
    points = [np.array(p, float) for p in shape]
    k = draw(st.integers(0, len(points) - 1))
    if draw(st.integers(0, 3)) == 0:  # swap two vertices: a bow-tie or a different outline
        m = draw(st.integers(0, len(points) - 1))
        points[k], points[m] = points[m], points[k]
    else:
        a = points[k]
        tip = np.array(draw(st.tuples(st.integers(-1, 5), st.integers(-1, 5))), float)
        t = draw(st.sampled_from([-1.0, -0.5, 0.0, 0.5, 1.0, 1.5, 2.0]))
        points[k + 1:k + 1] = [tip, a + t * (tip - a)]
    return draw(variant([tuple(p) for p in points]))


@pytest.mark.slow
@_settings(3000)
@given(grid_polygons())
def test_grid_polygons_agree_with_geos(points):
    compare('grid', points)


@pytest.mark.slow
@_settings(2500)
@given(rectilinear_polygons())
def test_rectilinear_polygons_agree_with_geos(points):
    compare('rectilinear', points)


@pytest.mark.slow
@_settings(1500)
@given(star_polygons())
def test_star_polygons_agree_with_geos(points):
    compare('star', points)


@_settings(1000)
@given(chamfered_polygons())
def test_chamfered_polygons_agree_with_geos(points):
    compare('chamfer', points)


@_settings(1200)
@given(sliver_polygons())
def test_sliver_polygons_agree_with_geos(points):
    compare('sliver', points)


@_settings(1000)
@given(detour_polygons())
def test_detour_polygons_agree_with_geos(points):
    compare('detour', points)


def test_at_least_10000_polygons_were_compared():
    if set(COMPARED) != set(FAMILIES):
        pytest.skip('counts only when every family ran')
    assert sum(COMPARED.values()) >= 10000, COMPARED
    # Zero disagreements: not even one where GEOS rounds (the sample is derandomised; such a
    # case, should one appear, is shown here with exact arithmetic backing our verdict).
    assert not GEOS_ROUNDED, [p.tolist() for p in GEOS_ROUNDED]


def test_geos_rounding_is_where_we_differ():
    # The grid point (-2, -3) is on the edge (-5, -1)-(-0.5, -4); moved by (0.3, -0.7) in
    # floating point it is 2**-106 (in the determinant) off it, which GEOS's double-double
    # orientation rounds to zero. Exact arithmetic, and so simple_polygon, says valid.
    # And the other way: an edge exactly back along its neighbour (a spike) that GEOS's
    # orientation rounds away from collinear, so GEOS says valid.
    points = np.array([[0.3, -0.7], [-3.7, -0.7], [-1.7, -3.7], [-4.7, -1.7], [-0.2, -4.7]])
    assert explain_validity(shapely.Polygon(points)) == 'Self-intersection[-1.7 -3.7]'
    a, b, c = ((Fraction(x), Fraction(y)) for x, y in points[[3, 4, 2]])
    assert _det(a, b, c) == Fraction(2) ** -106
    assert _geos_orientation(*points[[3, 4, 2]].tolist()) == 0
    assert exact_valid(points) and rounds_in_geos(points)
    simple_polygon(points)
    points = np.array([[-0.3742559466794155, -0.9216576642921853],
                       [-0.13357943983957773, -1.5040471517182028],
                       [-0.855608960359091, 0.24312131055984965],
                       [-2.9444904032233232, -1.3019742042255187]])
    assert geos_valid(points)
    a, b, c = ((Fraction(x), Fraction(y)) for x, y in points[:3])
    assert _det(a, b, c) == 0 and _geos_orientation(*points[:3].tolist()) != 0
    assert not exact_valid(points) and rounds_in_geos(points)
    with pytest.raises(PolygonError, match=r'edges 0 and 1 overlap .*\(a spike at vertex 1\)'):
        simple_polygon(points)
    # A triangle whose third vertex is exactly a quarter of the second: zero area (shapely
    # says so too), valid for GEOS, whose orientation of the three points is not zero.
    points = np.array([[0.0, 0.0], [-0.0105, 0.0045], [-0.002625, 0.001125]])
    assert np.array_equal(points[2] * 4, points[1])
    assert geos_valid(points) and shapely.Polygon(points).area == 0.0
    assert _geos_orientation(*points.tolist()) == 1 and rounds_in_geos(points)
    with pytest.raises(PolygonError, match='has zero area'):
        simple_polygon(points)


def test_exact_reference_agrees_on_near_degenerate_polygons():
    rng = np.random.default_rng(1)
    for _ in range(300):
        a = rng.normal(size=2)
        b = a + rng.normal(size=2)
        normal = np.array([a[1] - b[1], b[0] - a[0]])
        on = a + rng.choice([0.5, 1 / 3, rng.random(), 1.5]) * (b - a)
        points = np.array([a, b, b + normal, on, a + 0.5 * (b - a) + 2 * normal])
        try:
            simple_polygon(points)
            ours = True
        except PolygonError:
            ours = False
        assert ours == exact_valid(points), points.tolist()


@pytest.mark.parametrize('points', [
    [(0, 0), (4, 0), (4, 1), (3, 1), (3, 2), (2, 2), (2, 1), (1, 1), (1, 2), (0, 2)],
    [(0, 0), (1, 0), (2, 0), (2, 2), (0, 2)],
    [(0, 0), (2, 0), (2, 2), (0, 2), (0, 0)],
    [(0, 0), (2, 0), (2, 0), (2, 2), (0, 2)],
])
def test_notches_collinear_points_closed_rings_and_repeats_are_valid(points):
    assert geos_valid(np.array(points, float))
    simple_polygon(points)


def test_the_reason_names_the_edges_and_the_point():
    with pytest.raises(PolygonError, match=re.escape(
            'self-intersecting: edges 0 and 2 cross at (0.000, 0.000)')):
        simple_polygon([[-0.85, -0.45], [0.85, 0.45], [0.85, -0.45], [-0.85, 0.45]])
    with pytest.raises(PolygonError, match=re.escape(
            'self-intersecting: edges 0 and 2 meet at (0.100, 0.000)')):
        simple_polygon([(0, 0), (0.2, 0), (0.2, 0.2), (0.1, 0), (0, 0.2)])
    # Edges count in the points as written: the repeated vertex 1 shifts edge 2 to 3.
    with pytest.raises(PolygonError, match=re.escape(
            'self-intersecting: edges 0 and 3 meet at (0.100, 0.000)')):
        simple_polygon([(0, 0), (0.2, 0), (0.2, 0), (0.2, 0.2), (0.1, 0), (0, 0.2)])
    with pytest.raises(PolygonError, match=re.escape(
            'self-intersecting: edges 0 and 5 overlap along a stretch from (2.000, 0.000) '
            'to (3.000, 0.000)')):
        simple_polygon([(0, 0), (3, 0), (3, 2), (5, 2), (5, 0), (4, 0), (2, 0), (2, -1),
                        (0, -1)])
    with pytest.raises(PolygonError, match=re.escape(
            'self-intersecting: edges 2 and 3 overlap along a stretch from (2.000, 2.000) to '
            '(2.000, 3.000) (a spike at vertex 3)')):
        simple_polygon([(0, 0), (2, 0), (2, 1), (2, 3), (2, 2), (0, 2)])
    with pytest.raises(PolygonError, match='has zero area'):
        simple_polygon([(0, 0), (1, 0), (2, 0)])
    with pytest.raises(PolygonError, match='has fewer than 3 distinct points'):
        simple_polygon([(0, 0), (1, 0), (0, 0), (1, 0)])
    with pytest.raises(PolygonError, match='point 1 is not finite'):
        simple_polygon([(0, 0), (1, float('nan')), (0, 1)])


def test_notes_report_dropped_vertices():
    polygon = simple_polygon([(0, 0), (0, 0), (1, 0), (1, 1), (1, 1), (1, 1), (0, 1),
                              (0, 0)])
    assert polygon.notes == (
        'the last point repeats the first (a closed ring) and was dropped',
        'vertex 1 repeats vertex 0 and was dropped',
        'vertices 4 to 5 repeat vertex 3 and were dropped')
    assert polygon.points.tolist() == [[0, 0], [1, 0], [1, 1], [0, 1]]
    assert simple_polygon([(0, 0), (1, 0), (0, 1)]).notes == ()


def test_orientation_is_normalised_counter_clockwise():
    clockwise = [(0, 0), (0, 1), (1, 1), (1, 0)]
    polygon = simple_polygon(clockwise)
    assert polygon.points.tolist() == [[1, 0], [1, 1], [0, 1], [0, 0]]
    assert simple_polygon(polygon.points).points.tolist() == polygon.points.tolist()


def comb(teeth: int, spacing: float = 0.05) -> np.ndarray:
    """Return a comb of 4 * teeth + 2 vertices: teeth up from a base, their tops collinear."""
    top = []
    for k in reversed(range(teeth)):
        top += [(2 * k + 1, 1), (2 * k + 1, 2), (2 * k, 2), (2 * k, 1)]
    return np.array([(0, 0), (2 * teeth - 1, 0)] + top) * spacing


def test_a_5000_vertex_comb_and_star():
    points = comb(1250)
    assert len(points) == 5002
    assert len(simple_polygon(points).points) == 5002
    broken = points.copy()
    broken[2000, 0] += 0.075  # a tooth's corner pushed through its other side
    assert not geos_valid(broken)
    with pytest.raises(PolygonError, match=re.escape(
            'self-intersecting: edges 1998 and 2000 cross at (75.050, 0.083)')):
        simple_polygon(broken)
    angle = np.linspace(0.0, 2 * np.pi, 5000, endpoint=False)
    radius = np.where(np.arange(5000) % 2 == 0, 1.0, 0.2)
    star = np.column_stack([radius * np.cos(angle), radius * np.sin(angle)])
    assert len(simple_polygon(star).points) == 5000
    star[100] = star[2600] * 1.5  # a spike through the centre and out the other side
    with pytest.raises(PolygonError, match='self-intersecting: edges 99 and 2600 cross'):
        simple_polygon(star)


def test_orientation_is_exact():
    rng = np.random.default_rng(0)
    for _ in range(3000):
        a, b = rng.normal(size=2), rng.normal(size=2)
        t = rng.choice([0.5, 1 / 3, rng.random(), 2.0, -1.0])
        c = a + t * (b - a)  # on the line up to rounding: the filter cannot decide
        c = c + rng.choice([0.0, 2.0 ** -60, -(2.0 ** -60)]) * rng.normal(size=2)
        exact = (Fraction(a[0]) - Fraction(c[0])) * (Fraction(b[1]) - Fraction(c[1])) - \
            (Fraction(a[1]) - Fraction(c[1])) * (Fraction(b[0]) - Fraction(c[0]))
        assert orientation(a, b, c) == (exact > 0) - (exact < 0), (a, b, c)
    # Beyond the range of the error-free products the test falls back to fractions.
    assert orientation((0, 0), (1e-200, 0), (0.5e-200, 1e-320)) == 1
    assert orientation((0, 0), (1e200, 1e200), (3e200, 3e200)) == 0
    assert orientation((0, 0), (1e200, 1e200), (3e200, 3.0000000000000004e200)) == 1


@pytest.mark.parametrize('form', [COMPILED, INTERPRETED], ids=['compiled', 'interpreted'])
def test_touches_or_overlaps(form):
    square = [(0, 0), (1, 0), (1, 1), (0, 1)]
    assert touches_or_overlaps(square, [(1, 1), (2, 1), (2, 2)], form)  # a corner
    assert touches_or_overlaps(square, [(1, 0.2), (2, 0.2), (2, 0.8), (1, 0.8)], form)  # wall
    assert touches_or_overlaps(square, [(0.2, 0.2), (0.4, 0.2), (0.4, 0.4)], form)  # inside
    assert touches_or_overlaps([(0.2, 0.2), (0.4, 0.2), (0.4, 0.4)], square, form)
    assert touches_or_overlaps(square, [(0.5, 0.5), (3, 0.5), (3, 3)], form)  # crossing
    # Collinear with a wall but apart from it: the old segment test said they touch.
    assert not touches_or_overlaps(square, [(2, 0), (3, 0), (3, 1)], form)
    assert not touches_or_overlaps(square, [(1.5, 1.5), (2, 1.5), (2, 2)], form)


@pytest.mark.parametrize('form', [COMPILED, INTERPRETED], ids=['compiled', 'interpreted'])
def test_a_coordinate_too_small_for_the_fast_arithmetic_is_still_judged_exactly(form):
    # 1e-300 is below 2**-300: the turns that involve it are decided with fractions (in
    # compiled code through numba's object mode).
    square = np.array([[0.0, 0.0], [1.0, 1e-300], [1.0, 1.0], [0.0, 1.0]])
    assert simple_polygon(square, form).points.shape == (4, 2)
    assert geos_valid(square)
    bowtie = np.array([[0.0, 0.0], [1.0, 1e-300], [0.0, 1.0], [1.0, 1.0]])
    with pytest.raises(PolygonError, match='self-intersecting: edges 1 and 3'):
        simple_polygon(bowtie, form)
    assert not geos_valid(bowtie)
    # A vertex exactly on an edge, found although the edge's end is 1e-300 off the axis.
    touching = np.array([[0.0, 0.0], [2.0, 2e-300], [2.0, 1.0], [1.0, 1e-300], [0.0, 1.0]])
    with pytest.raises(PolygonError, match='meet at'):
        simple_polygon(touching)
    assert exact_valid(touching) is False
