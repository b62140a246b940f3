"""
Vectorised collision and clearance of the arm against the enclosure (bulk checker).

The robot is four bodies: three link capsules (a segment swept by a radius) and the wafer
disc (a zero-length segment at the wafer centre swept by the wafer radius). The enclosure is
the boundary polygon (the robot stays inside) and obstacle polygons (the robot stays
outside). A body's clearance is its distance to the nearest polygon edge minus its radius;
crossing an edge counts as distance zero. Because the arm is a chain from the shoulder,
which the cell model requires to be in free space, a body cannot leave the boundary or enter
an obstacle without crossing an edge, so edge distances decide collision exactly. This is
the fast path used to build the roadmap; ``fcl_model`` is the reference it is tested against.
"""

from dataclasses import dataclass

import numpy as np

from wafer_planner_ros.geometry import point_segment_distance
from wafer_planner_ros.kinematics import PlanarArm

_CHUNK = 16384  # configurations per vectorised batch: bounds temporary memory to ~10 MB


@dataclass(frozen=True)
class Contact:
    """The closest body/obstacle pair of one configuration."""

    body: str
    obstacle: str
    clearance: float
    """Distance minus radius (m); <= 0 means in collision."""
    crossing: bool
    """The body's spine crosses the obstacle's outline: the depth of overlap is unknown."""


class ClearanceModel:
    """Per-body clearance of arm configurations against the boundary and obstacles."""

    def __init__(self, arm: PlanarArm, body_radii, body_names, boundary, obstacles=(),
                 obstacle_names=None):
        """
        Build the model.

        ``body_radii``/``body_names``: the three link radii then the wafer radius (m).
        ``boundary``: (V, 2) polygon; ``obstacles``: sequence of (V_j, 2) polygons.
        """
        self.arm = arm
        self.radii = np.asarray(body_radii, dtype=float)
        self.body_names = tuple(body_names)
        polygons = [np.asarray(boundary, float)] + [np.asarray(o, float) for o in obstacles]
        self.owner_names = ('boundary',) + tuple(
            obstacle_names or (f'cell.obstacles[{j}]' for j in range(len(obstacles))))
        starts, owners, start_vertex, end_vertex = [], [], [], []
        offset = 0
        for owner, polygon in enumerate(polygons):
            n = len(polygon)
            starts.append(polygon)
            owners.append(np.full(n, owner))
            start_vertex.append(offset + np.arange(n))
            end_vertex.append(offset + (np.arange(n) + 1) % n)
            offset += n
        self.vertices = np.concatenate(starts)
        self.edge_owner = np.concatenate(owners)
        self._start_vertex = np.concatenate(start_vertex)
        self._end_vertex = np.concatenate(end_vertex)
        self.edge_start = self.vertices[self._start_vertex]
        self.edge_end = self.vertices[self._end_vertex]
        self._edge_vec = self.edge_end - self.edge_start
        self._edge_len_sq = np.sum(self._edge_vec ** 2, axis=-1)
        self._base_dist = point_segment_distance(
            arm.base, self.edge_start, self._edge_vec, self._edge_len_sq)
        self.polygons = tuple(polygons)

    @property
    def body_count(self) -> int:
        """Return the number of bodies (links and wafer)."""
        return len(self.radii)

    def edge_distances(self, q: np.ndarray) -> np.ndarray:
        """Return the distance of each body's spine to each edge (m), shape (N, 4, E)."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        geometry = self._spines(q)
        return np.stack([self._to_edge(geometry, e) for e in range(len(self.edge_start))],
                        axis=-1)

    def _spines(self, q: np.ndarray) -> tuple:
        """Return the link spines' coordinates, as separate x/y arrays (fast in numpy)."""
        points = self.arm.joint_points(q)
        x, y = points[..., 0], points[..., 1]             # base, elbow, wrist, centre
        ax, ay, bx, by = x[:, :3], y[:, :3], x[:, 1:], y[:, 1:]
        abx, aby = bx - ax, by - ay
        return ax, ay, bx, by, abx, aby, np.maximum(abx * abx + aby * aby, 1e-300)

    def _to_edge(self, geometry: tuple, e: int) -> np.ndarray:
        """Return the distance (N, 4) of every body's spine to edge e."""
        ax, ay, bx, by, abx, aby, ab2 = geometry
        (cx, cy), (dx, dy) = self.edge_start[e], self.edge_end[e]
        ex, ey = dx - cx, dy - cy
        # Elbow, wrist and wafer centre (the links' far ends) to the edge.
        s = np.clip(((bx - cx) * ex + (by - cy) * ey) / self._edge_len_sq[e], 0.0, 1.0)
        px, py = bx - cx - s * ex, by - cy - s * ey
        ends = np.sqrt(px * px + py * py)
        starts = np.empty_like(ends)
        starts[:, 0] = self._base_dist[e]
        starts[:, 1:] = ends[:, :2]
        links = np.minimum(ends, starts)
        # The edge's two vertices to each link.
        for vx, vy in ((cx, cy), (dx, dy)):
            t = np.clip(((vx - ax) * abx + (vy - ay) * aby) / ab2, 0.0, 1.0)
            wx, wy = vx - ax - t * abx, vy - ay - t * aby
            links = np.minimum(links, np.sqrt(wx * wx + wy * wy))
        # A link crossing the edge is at distance zero.
        side_c = abx * (cy - ay) - aby * (cx - ax)
        side_d = abx * (dy - ay) - aby * (dx - ax)
        side_a = ex * (ay - cy) - ey * (ax - cx)
        side_b = ex * (by - cy) - ey * (bx - cx)
        links[(side_c * side_d <= 0.0) & (side_a * side_b <= 0.0)] = 0.0
        return np.concatenate([links, ends[:, 2:]], axis=1)

    def body_clearance(self, q: np.ndarray) -> np.ndarray:
        """
        Return each body's clearance (m) for configurations (N, 3), shape (N, 4).

        Where every body's clearance is positive the configuration is free. In a colliding
        configuration only the non-positive values mean something: a body beyond a link that
        crosses the boundary can be wholly outside it and still show a positive value.
        """
        q = np.atleast_2d(np.asarray(q, dtype=float))
        out = np.empty((len(q), len(self.radii)))
        for lo in range(0, len(q), _CHUNK):
            geometry = self._spines(q[lo:lo + _CHUNK])
            nearest = self._to_edge(geometry, 0)
            for e in range(1, len(self.edge_start)):
                np.minimum(nearest, self._to_edge(geometry, e), out=nearest)
            out[lo:lo + _CHUNK] = nearest
        return out - self.radii

    def clearance(self, q: np.ndarray) -> np.ndarray:
        """Return the smallest body clearance of each configuration in m, shape (N,)."""
        return self.body_clearance(q).min(axis=-1)

    def in_collision(self, q: np.ndarray) -> np.ndarray:
        """Return whether each configuration (N, 3) touches or penetrates an obstacle."""
        return self.clearance(q) <= 0.0

    def contact(self, q: np.ndarray) -> Contact:
        """Return the closest body/obstacle pair of one configuration (3,)."""
        gaps = self.edge_distances(q)[0] - self.radii[:, None]
        body, edge = np.unravel_index(np.argmin(gaps), gaps.shape)
        return Contact(body=self.body_names[body],
                       obstacle=self.owner_names[self.edge_owner[edge]],
                       clearance=float(gaps[body, edge]),
                       crossing=bool(gaps[body, edge] == -self.radii[body]))
