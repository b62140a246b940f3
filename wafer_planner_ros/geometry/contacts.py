"""
Which body of the robot is nearest to a wall, or collides with one, and where.

For one configuration, each body (the three link capsules from the shoulder out, then the
wafer disc) with the wall or obstacle nearest to it: its clearance exactly as
``ClearanceModel`` measures it, the pair of nearest points (one on the body's spine, one on
the outline) and whether the body collides. A body collides when its clearance is not
positive (it touches, overlaps or crosses an outline, or comes within the clearance margin)
or when its spine lies on the wrong side of one: beyond the boundary or inside an
obstacle, where a link crossing the outline carries the bodies after it. Such a body may be
far from every edge, so its clearance says nothing; it is marked ``outside``.
"""

from dataclasses import dataclass
from typing import Optional, Tuple

import numpy as np

from wafer_planner_ros.geometry.clearance import ClearanceModel, Contact
from wafer_planner_ros.geometry.planar import cross2, points_in_polygon


@dataclass(frozen=True, eq=False)
class BodyContact(Contact):
    """One body of one configuration and the outline nearest to it."""

    index: int = 0
    """The body: 0, 1, 2 the links from the shoulder out, 3 the wafer."""
    owner: int = 0
    """The outline: 0 the boundary, j + 1 obstacle j (``ClearanceModel.polygons``)."""
    edge: int = 0
    """The outline's edge nearest to the body (``ClearanceModel.edge_start``/``edge_end``)."""
    spine_point: Optional[np.ndarray] = None
    """(2,) the nearest point of the body's spine (the link's axis, the wafer's centre), m."""
    wall_point: Optional[np.ndarray] = None
    """(2,) the nearest point of the outline (where they cross, the crossing), m."""
    colliding: bool = False
    """The body touches or overlaps the outline, or is within the margin, or ``outside``."""
    outside: bool = False
    """The body's spine lies beyond the boundary or inside the obstacle: most or all of it."""
    radius: float = 0.0
    """The body's own radius (m; the margin not included)."""

    def describe(self) -> str:
        """Return e.g. 'wafer vs boundary, overlap 20.0 mm', '..., 3.1 mm apart', 'crosses'."""
        if self.outside:
            where = 'beyond' if self.obstacle == 'boundary' else 'inside'
            return f'{self.body} {where} {self.obstacle}'
        if self.crossing:
            return f'{self.body} crosses {self.obstacle}'
        if not self.colliding:
            return (f'{self.body} vs {self.obstacle}, '
                    f'{(self.clearance + self.margin) * 1000:.1f} mm apart')
        return super().describe()

    def surface_point(self) -> np.ndarray:
        """Return the point of the body's surface nearest to the outline (m)."""
        offset = self.wall_point - self.spine_point
        length = float(np.hypot(*offset))
        if length == 0.0:
            return self.spine_point
        return self.spine_point + offset * min(self.radius / length, 1.0)


def body_contacts(model: ClearanceModel, q) -> Tuple[BodyContact, ...]:
    """Return the contact of each body of configuration q (3,): links, then the wafer."""
    q = np.asarray(q, float).reshape(3)
    gaps = model.edge_distances(q)[0]                       # (bodies, edges) spine distances
    points = model.arm.joint_points(q)
    spines = [(points[k], points[k + 1]) for k in range(3)] + [(points[3], points[3])]
    inside_boundary = points_in_polygon(points[1:], model.polygons[0])
    found = []
    for k, (a, b) in enumerate(spines):
        wrong = _wrong_side(model, b, bool(inside_boundary[min(k, 2)]))
        edges = np.arange(len(gaps[k])) if wrong is None else np.nonzero(
            model.edge_owner == wrong)[0]
        edge = int(edges[np.argmin(gaps[k, edges])])
        clearance = float(gaps[k, edge] - model.radii[k])
        spine_point, wall_point = nearest_points(a, b, model.edge_start[edge],
                                                 model.edge_end[edge])
        outside = wrong is not None and gaps[k, edge] > 0.0  # not crossing: on the wrong side
        owner = int(model.edge_owner[edge])
        found.append(BodyContact(
            body=model.body_names[k], obstacle=model.owner_names[owner], clearance=clearance,
            crossing=bool(gaps[k, edge] == 0.0), margin=model.margin, index=k, owner=owner,
            edge=edge,
            spine_point=spine_point, wall_point=wall_point,
            colliding=bool(clearance <= 0.0 or outside), outside=bool(outside),
            radius=float(model.radii[k] - model.margin)))
    return tuple(found)


def colliding(model: ClearanceModel, q) -> Tuple[BodyContact, ...]:
    """Return the contacts of the bodies of configuration q that collide (none: free)."""
    return tuple(c for c in body_contacts(model, q) if c.colliding)


def nearest_points(a, b, c, d) -> Tuple[np.ndarray, np.ndarray]:
    """
    Return the nearest points (p on a-b, w on c-d) of two segments in the plane.

    Crossing segments give their crossing twice. Otherwise one of the four ends is one of
    the nearest points, as in the clearance kernel.
    """
    a, b, c, d = (np.asarray(v, float) for v in (a, b, c, d))
    ab, cd = b - a, d - c
    denominator = cross2(ab, cd)
    if denominator != 0.0:
        s = cross2(c - a, cd) / denominator
        t = cross2(c - a, ab) / denominator
        if 0.0 <= s <= 1.0 and 0.0 <= t <= 1.0:
            crossing = a + s * ab
            return crossing, crossing.copy()
    candidates = [(a, _onto(a, c, cd)), (b, _onto(b, c, cd)),
                  (_onto(c, a, ab), c), (_onto(d, a, ab), d)]
    return min(candidates, key=lambda pair: float(np.hypot(*(pair[0] - pair[1]))))


def _onto(p: np.ndarray, a: np.ndarray, ab: np.ndarray) -> np.ndarray:
    """Return the point of segment a + s ab, s in [0, 1], nearest to p."""
    length_sq = float(ab @ ab)
    s = 0.0 if length_sq == 0.0 else min(max(float((p - a) @ ab) / length_sq, 0.0), 1.0)
    return a + s * ab


def _wrong_side(model: ClearanceModel, point: np.ndarray, inside: bool) -> Optional[int]:
    """Return the polygon (0: the boundary) ``point`` is on the wrong side of, or None."""
    if not inside:
        return 0
    for owner, polygon in enumerate(model.polygons[1:], 1):
        if points_in_polygon(point, polygon):
            return owner
    return None
