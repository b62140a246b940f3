"""
Reference collision model on python-fcl.

Link capsules and a wafer sphere move in the z = 0 plane; the enclosure is made of tall
triangular prisms: a constrained triangulation of (a large box minus the boundary polygon)
and of every obstacle polygon, so non-convex boundaries and obstacles are exact. Prisms are
much taller than the robot so that penetration is never reported along z.

The prisms decide collision. Distances come from zero-radius capsules along the polygon
edges instead: fcl measures capsule/sphere against capsule with exact closed-form routines,
whereas its GJK distance from a capsule to a convex prism is not exact (off by up to
millimetres, thin triangles being the worst; doc/how-it-works.md). For a robot in free
space the distance to the enclosure is the distance to its nearest edge, so both give the
same quantity. This model is slow (Python-side transforms per query) and serves as the
ground truth that the vectorised ``clearance`` model and every published trajectory are
checked against.
"""

import fcl
import numpy as np
import shapely
from wafer_planner_ros.geometry.planar import cross2

_HALF_HEIGHT = 1.0  # m: prisms span z in [-1, 1]; the robot lies at z = 0
_MARGIN = 2.0       # m: the box around the boundary whose remainder is the wall


def _prism(triangle: np.ndarray) -> fcl.CollisionObject:
    """Return a tall prism over a counter-clockwise triangle (3, 2)."""
    bottom = np.column_stack([triangle, np.full(3, -_HALF_HEIGHT)])
    top = np.column_stack([triangle, np.full(3, _HALF_HEIGHT)])
    vertices = np.vstack([bottom, top])
    faces = np.array([3, 0, 2, 1, 3, 3, 4, 5,
                      4, 0, 1, 4, 3, 4, 1, 2, 5, 4, 4, 2, 0, 3, 5], dtype=np.int64)
    return fcl.CollisionObject(fcl.Convex(vertices, 5, faces))


def _triangles(geometry) -> list:
    """Return the counter-clockwise triangles (3, 2) of a constrained triangulation."""
    out = []
    for tri in shapely.constrained_delaunay_triangles(geometry).geoms:
        corners = np.asarray(tri.exterior.coords)[:3]
        if shapely.Polygon(corners).area <= 0.0:
            continue
        if cross2(corners[1] - corners[0], corners[2] - corners[0]) < 0:
            corners = corners[::-1]
        out.append(corners)
    return out


def _rotation_z(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


# fcl capsules lie along z: turn them onto +x first.
_Z_TO_X = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])


def _manager(objects: list) -> fcl.DynamicAABBTreeCollisionManager:
    manager = fcl.DynamicAABBTreeCollisionManager()
    manager.registerObjects(objects)
    manager.setup()
    return manager


def _segment_transform(a: np.ndarray, b: np.ndarray, angle: float) -> fcl.Transform:
    """Return the pose of a capsule whose axis runs from a to b (heading ``angle``)."""
    middle = 0.5 * (a + b)
    return fcl.Transform(_rotation_z(angle) @ _Z_TO_X, np.array([middle[0], middle[1], 0.0]))


def _segment(a: np.ndarray, b: np.ndarray) -> fcl.CollisionObject:
    """Return a zero-radius capsule from a to b in the z = 0 plane."""
    d = b - a
    return fcl.CollisionObject(fcl.Capsule(0.0, float(np.hypot(*d))),
                               _segment_transform(a, b, float(np.arctan2(d[1], d[0]))))


class FclModel:
    """Collision and clearance of the arm in the enclosure, computed by fcl."""

    def __init__(self, arm, body_radii, boundary, obstacles=()):
        """Build the enclosure prisms and the robot's fcl objects (same inputs as clearance)."""
        self.arm = arm
        radii = np.asarray(body_radii, float)
        boundary = shapely.Polygon(boundary)
        xmin, ymin, xmax, ymax = boundary.bounds
        outer = shapely.box(xmin - _MARGIN, ymin - _MARGIN, xmax + _MARGIN, ymax + _MARGIN)
        triangles = _triangles(outer.difference(boundary))
        for obstacle in obstacles:
            triangles += _triangles(shapely.Polygon(obstacle))
        self._walls = [_prism(t) for t in triangles]
        corners = np.array(triangles)                       # (P, 3, 2)
        self._wall_low, self._wall_high = corners.min(axis=1), corners.max(axis=1)
        self._radii = radii
        self._env = _manager(self._walls)
        edges = [np.asarray(boundary.exterior.coords)]
        edges += [np.asarray(shapely.Polygon(o).exterior.coords) for o in obstacles]
        self._edges = _manager([_segment(a, b) for ring in edges
                                for a, b in zip(ring[:-1], ring[1:])])
        lengths = arm.link_lengths
        self._links = [fcl.CollisionObject(fcl.Capsule(radii[i], lengths[i])) for i in range(3)]
        self._wafer = fcl.CollisionObject(fcl.Sphere(radii[3]))
        self._robot = _manager(self._links + [self._wafer])

    def _place(self, q: np.ndarray) -> None:
        points = self.arm.joint_points(q)
        angles = self.arm.absolute_angles(q)
        for link, a, b, angle in zip(self._links, points[:-1], points[1:], angles):
            link.setTransform(_segment_transform(a, b, angle))
        centre = points[3]
        self._wafer.setTranslation(np.array([centre[0], centre[1], 0.0]))
        self._robot.update()

    def in_collision(self, q: np.ndarray) -> bool:
        """Return whether configuration q (3,) collides with the enclosure."""
        self._place(np.asarray(q, float))
        data = fcl.CollisionData(request=fcl.CollisionRequest())
        self._robot.collide(self._env, data, fcl.defaultCollisionCallback)
        return bool(data.result.is_collision)

    def in_collision_many(self, q: np.ndarray) -> np.ndarray:
        """
        Return whether each configuration (N, 3) collides, for millions of configurations.

        The broad phase is vectorised in numpy (a body and a prism can only touch when their
        axis-aligned boxes overlap, as in fcl's own broad phase); every overlapping pair then
        goes to fcl's narrow phase, which alone decides.
        """
        q = np.atleast_2d(np.asarray(q, float))
        points = self.arm.joint_points(q)                                # (N, 4, 2)
        spine_a = points                                                 # links, then wafer
        spine_b = np.concatenate([points[:, 1:], points[:, 3:]], axis=1)
        low = np.minimum(spine_a, spine_b) - self._radii[:, None]        # (N, 4, 2)
        high = np.maximum(spine_a, spine_b) + self._radii[:, None]
        overlap = np.all((low[:, :, None] <= self._wall_high) &
                         (high[:, :, None] >= self._wall_low), axis=-1)  # (N, 4, P)
        hit = np.zeros(len(q), dtype=bool)
        angles = self.arm.absolute_angles(q)
        request = fcl.CollisionRequest()
        bodies = self._links + [self._wafer]
        for n, body, wall in zip(*np.nonzero(overlap)):
            if hit[n]:
                continue
            if body < 3:
                bodies[body].setTransform(_segment_transform(
                    points[n, body], points[n, body + 1], angles[n, body]))
            else:
                self._wafer.setTranslation(np.array([points[n, 3, 0], points[n, 3, 1], 0.0]))
            hit[n] = fcl.collide(bodies[body], self._walls[wall], request,
                                 fcl.CollisionResult()) > 0
        return hit

    def clearance(self, q: np.ndarray) -> float:
        """Return the distance (m) from the robot at q to the enclosure (<= 0 in collision)."""
        if self.in_collision(q):
            return 0.0
        data = fcl.DistanceData(request=fcl.DistanceRequest())
        self._robot.distance(self._edges, data, fcl.defaultDistanceCallback)
        return float(data.result.min_distance)
