"""Planar geometry: polygons and vectorised point/segment distances (metres)."""

import numpy as np


def cross2(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Return the z component of the cross product of 2-vectors (broadcasting)."""
    return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]


def polygon_edges(polygon: np.ndarray) -> tuple:
    """Return the start and end points (each (E, 2)) of a closed polygon's edges."""
    return polygon, np.roll(polygon, -1, axis=0)


def point_segment_distance(p, a, ab, ab_sq) -> np.ndarray:
    """
    Return the distance from points p to segments a + s*ab, s in [0, 1] (broadcasting).

    ``ab_sq`` is ``|ab|**2``; zero-length segments are allowed.
    """
    ap = p - a
    s = np.clip(np.sum(ap * ab, axis=-1) / np.maximum(ab_sq, 1e-300), 0.0, 1.0)
    diff = ap - s[..., None] * ab
    return np.sqrt(np.sum(diff * diff, axis=-1))


def points_in_polygon(points: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """Return whether each point (..., 2) lies strictly inside the polygon (even-odd rule)."""
    start, end = polygon_edges(polygon)
    px = points[..., 0, None]
    py = points[..., 1, None]
    y0, y1 = start[:, 1], end[:, 1]
    crosses = (y0 > py) != (y1 > py)
    with np.errstate(divide='ignore', invalid='ignore'):
        x_at = start[:, 0] + (py - y0) * (end[:, 0] - start[:, 0]) / (y1 - y0)
    return (np.count_nonzero(crosses & (px < x_at), axis=-1) % 2) == 1
