"""
Vectorised collision and clearance of the arm against the enclosure (bulk checker).

The robot is four bodies: three link capsules (a segment swept by a radius) and the wafer
disc (a zero-length segment at the wafer centre swept by the wafer radius). The enclosure is
the boundary polygon (the robot stays inside) and obstacle polygons (the robot stays
outside). A body's clearance is its distance to the nearest polygon edge minus its radius
and the clearance margin (every body is grown by it); crossing an edge counts as distance
zero. Because the arm is a chain from the shoulder,
which the cell model requires to be in free space, a body cannot leave the boundary or enter
an obstacle without crossing an edge, so edge distances decide collision exactly. This is
the fast path used to build the roadmap; ``fcl_model`` is the reference it is tested against.
"""

from dataclasses import dataclass

from numba import njit
import numpy as np

from wafer_planner_ros.geometry.kinematics import PlanarArm
from wafer_planner_ros.geometry.planar import point_segment_distance


@dataclass(frozen=True)
class Contact:
    """The closest body/obstacle pair of one configuration."""

    body: str
    obstacle: str
    clearance: float
    """Distance minus radius minus margin (m); <= 0 means in collision."""
    crossing: bool
    """The body's spine crosses the obstacle's outline: the depth of overlap is unknown."""
    margin: float = 0.0
    """The clearance margin the model keeps (m)."""

    def describe(self) -> str:
        """Return e.g. 'wafer vs boundary, 1.2 mm overlap' for messages."""
        pair = f'{self.body} vs {self.obstacle}'
        distance = self.clearance + self.margin
        if self.crossing:
            return pair
        if distance <= 0.0:
            return f'{pair}, overlap {-distance * 1000:.1f} mm'
        return (f'{pair}, {distance * 1000:.1f} mm apart: within the clearance margin of '
                f'{self.margin * 1000:.1f} mm')


class ClearanceModel:
    """Per-body clearance of arm configurations against the boundary and obstacles."""

    def __init__(self, arm: PlanarArm, body_radii, body_names, boundary, obstacles=(),
                 obstacle_names=None, margin: float = 0.0):
        """
        Build the model.

        ``body_radii``/``body_names``: the three link radii then the wafer radius (m).
        ``boundary``: (V, 2) polygon; ``obstacles``: sequence of (V_j, 2) polygons.
        ``margin``: the distance (m) to keep; every body is grown by it, so that every
        clearance below is the distance beyond the margin.
        """
        self.arm = arm
        self.margin = float(margin)
        self.radii = np.asarray(body_radii, dtype=float) + self.margin
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
        return self._distances(q, per_edge=True)

    def body_clearance(self, q: np.ndarray) -> np.ndarray:
        """
        Return each body's clearance (m) for configurations (N, 3), shape (N, 4).

        Where every body's clearance is positive the configuration is free. In a colliding
        configuration only the non-positive values mean something: a body beyond a link that
        crosses the boundary can be wholly outside it and still show a positive value.
        """
        q = np.asarray(q, dtype=float)
        clearance = self._distances(q, per_edge=False) - self.radii
        # The kernel's min() passes over NaN: a configuration that is not finite is nowhere.
        clearance[~np.isfinite(q.reshape(-1, 3)).all(axis=1)] = -np.inf
        return clearance

    def _distances(self, q: np.ndarray, per_edge: bool) -> np.ndarray:
        q = np.ascontiguousarray(np.atleast_2d(np.asarray(q, dtype=float)))
        out = _spine_distances(q, np.asarray(self.arm.base, float),
                               np.asarray(self.arm.link_lengths, float), self.edge_start,
                               self.edge_end, self._edge_len_sq, self._base_dist, per_edge)
        return out if per_edge else out[:, :, 0]

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
                       crossing=bool(gaps[body, edge] == -self.radii[body]),
                       margin=self.margin)


@njit(cache=True, nogil=True)
def _spine_distances(q, base, link_lengths, edge_start, edge_end, edge_len_sq, base_dist,
                     per_edge):
    """
    Return each body's spine distance to every edge (N, 4, E), or to the nearest (N, 4, 1).

    The links are the segments base-elbow, elbow-wrist, wrist-centre; the wafer's spine is
    the centre. A link crossing an edge is at distance zero.
    """
    edges = len(edge_start)
    out = np.empty((len(q), 4, edges if per_edge else 1))
    x, y = np.empty(4), np.empty(4)
    for n in range(len(q)):
        x[0], y[0] = base[0], base[1]
        theta, cx_, cy_ = 0.0, 0.0, 0.0
        for j in range(3):  # joint points: base + cumulative link vectors
            theta += q[n, j]
            cx_ += link_lengths[j] * np.cos(theta)
            cy_ += link_lengths[j] * np.sin(theta)
            x[j + 1], y[j + 1] = base[0] + cx_, base[1] + cy_
        out[n] = np.inf
        for e in range(edges):
            cx, cy = edge_start[e, 0], edge_start[e, 1]
            dx, dy = edge_end[e, 0], edge_end[e, 1]
            ex, ey = dx - cx, dy - cy
            start = base_dist[e]
            column = e if per_edge else 0
            for j in range(3):
                ax, ay, bx, by = x[j], y[j], x[j + 1], y[j + 1]
                # The link's far end to the edge.
                s = min(max(((bx - cx) * ex + (by - cy) * ey) / edge_len_sq[e], 0.0), 1.0)
                px, py = bx - cx - s * ex, by - cy - s * ey
                end = np.sqrt(px * px + py * py)
                gap = min(end, start)
                # The edge's two vertices to the link.
                abx, aby = bx - ax, by - ay
                ab2 = max(abx * abx + aby * aby, 1e-300)
                for vx, vy in ((cx, cy), (dx, dy)):
                    t = min(max(((vx - ax) * abx + (vy - ay) * aby) / ab2, 0.0), 1.0)
                    wx, wy = vx - ax - t * abx, vy - ay - t * aby
                    gap = min(gap, np.sqrt(wx * wx + wy * wy))
                side_c = abx * (cy - ay) - aby * (cx - ax)
                side_d = abx * (dy - ay) - aby * (dx - ax)
                side_a = ex * (ay - cy) - ey * (ax - cx)
                side_b = ex * (by - cy) - ey * (bx - cx)
                if side_c * side_d <= 0.0 and side_a * side_b <= 0.0:
                    gap = 0.0
                out[n, j, column] = min(out[n, j, column], gap)
                start = end
            out[n, 3, column] = min(out[n, 3, column], start)  # the wafer centre
    return out
