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
``ClearanceModel.body_clearance_gradient`` adds each body's clearance gradient with respect to
the joint angles, for the constraints of a trajectory optimiser.
"""

from dataclasses import dataclass

import numpy as np

from wafer_planner_ros import kernels
from wafer_planner_ros.geometry.kinematics import PlanarArm
from wafer_planner_ros.geometry.planar import point_segment_distance
from wafer_planner_ros.kernels import kernel

INTERPRETED_WORK = 2000
"""Configurations x edges up to which a clearance runs interpreted until numba is loaded."""


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

    def body_clearance_gradient(self, q: np.ndarray) -> tuple:
        """
        Return each body's clearance (N, 4) and its gradient d clearance / d q (N, 4, 3).

        The clearance equals ``body_clearance(q)`` exactly; the margin shifts it and leaves
        the gradient alone. The gradient is that of the nearest edge's witness pair (the
        envelope theorem): with p the nearest point of the body's spine and n the unit vector
        from the edge's nearest point to p, the entry of joint i is n . (z x (p - joint_i))
        for the joints that move the body, and 0 for the joints beyond it.

        It is the gradient of a minimum, so it is not defined everywhere; there it is
        - the gradient of the first nearest edge (in polygon order) and witness pair where
          two of them tie: a one-sided gradient, exact again once the tie is left;
        - 0 where the spine touches or crosses an edge (distance zero, clearance equal to
          minus the radius), which is a collision anyway;
        - 0, with clearance -inf, where the configuration is not finite.
        """
        q = np.asarray(q, dtype=float)
        distance, gradient = _spine_distance_gradients(
            np.ascontiguousarray(np.atleast_2d(q)), np.asarray(self.arm.base, float),
            np.asarray(self.arm.link_lengths, float), self.edge_start, self.edge_end,
            self._edge_len_sq, self._base_dist)
        clearance = distance - self.radii
        # As in body_clearance: a configuration that is not finite is nowhere.
        finite = np.isfinite(q.reshape(-1, 3)).all(axis=1)
        clearance[~finite] = -np.inf
        gradient[~finite] = 0.0
        return clearance, gradient

    def _distances(self, q: np.ndarray, per_edge: bool) -> np.ndarray:
        q = np.ascontiguousarray(np.atleast_2d(np.asarray(q, dtype=float)))
        # A few configurations (a cell file's stations) are checked without loading numba.
        form = kernels.sized(len(q) * len(self.edge_start), INTERPRETED_WORK)
        out = form(_spine_distances)(q, np.asarray(self.arm.base, float),
                                     np.asarray(self.arm.link_lengths, float),
                                     self.edge_start, self.edge_end, self._edge_len_sq,
                                     self._base_dist, per_edge)
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


@kernel(nogil=True)
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
        _joint_points(q[n], base, link_lengths, x, y)
        out[n] = np.inf
        for e in range(edges):
            cx, cy = edge_start[e, 0], edge_start[e, 1]
            dx, dy = edge_end[e, 0], edge_end[e, 1]
            start = base_dist[e]
            column = e if per_edge else 0
            for j in range(3):
                # The witness outputs are not used here: the compiler drops their arithmetic.
                gap, end = _link_to_edge(x[j], y[j], x[j + 1], y[j + 1], cx, cy, dx, dy,
                                         edge_len_sq[e], start, 0.0, 0.0)[:2]
                out[n, j, column] = min(out[n, j, column], gap)
                start = end
            out[n, 3, column] = min(out[n, 3, column], start)  # the wafer centre
    return out


@kernel(nogil=True)
def _spine_distance_gradients(q, base, link_lengths, edge_start, edge_end, edge_len_sq,
                              base_dist):
    """
    Return each body's spine distance to the nearest edge (N, 4) and its gradient (N, 4, 3).

    The distances are those of ``_spine_distances``, by the same operations in the same
    order, so bit for bit. For the nearest edge of each body, with the witness pair of
    ``_link_to_edge`` (p on the body's spine at a fixed parameter along its link, u = p minus
    the edge's point), the envelope theorem gives d distance / d q_i = (u / |u|) .
    (z x (p - joint_i)) for the joints i up to the body's own link (the wafer moves with
    all three) and 0 for later joints. Where the distance is zero (the spine touches or
    crosses an edge) the gradient is not defined and is left at 0.
    """
    edges = len(edge_start)
    dist = np.empty((len(q), 4))
    grad = np.zeros((len(q), 4, 3))
    x, y = np.empty(4), np.empty(4)
    best = np.empty(4)  # per body, the nearest witness so far: distance, p and u
    best_px, best_py = np.empty(4), np.empty(4)
    best_ux, best_uy = np.empty(4), np.empty(4)
    for n in range(len(q)):
        _joint_points(q[n], base, link_lengths, x, y)
        dist[n] = np.inf
        best[:] = np.inf
        for e in range(edges):
            cx, cy = edge_start[e, 0], edge_start[e, 1]
            dx, dy = edge_end[e, 0], edge_end[e, 1]
            start = base_dist[e]
            # The base does not move, so the direction of its offset does not matter.
            start_ux, start_uy = 0.0, 0.0
            for j in range(3):
                gap, end, end_ux, end_uy, near, near_px, near_py, near_ux, near_uy = (
                    _link_to_edge(x[j], y[j], x[j + 1], y[j + 1], cx, cy, dx, dy,
                                  edge_len_sq[e], start, start_ux, start_uy))
                dist[n, j] = min(dist[n, j], gap)
                if near < best[j]:
                    best[j], best_px[j], best_py[j] = near, near_px, near_py
                    best_ux[j], best_uy[j] = near_ux, near_uy
                start, start_ux, start_uy = end, end_ux, end_uy
            dist[n, 3] = min(dist[n, 3], start)  # the wafer centre
            if start < best[3]:
                best[3], best_px[3], best_py[3] = start, x[3], y[3]
                best_ux[3], best_uy[3] = start_ux, start_uy
        for k in range(4):
            if not 0.0 < best[k] < np.inf:
                continue  # touching or crossing, or not finite: no gradient
            nx, ny = best_ux[k] / best[k], best_uy[k] / best[k]
            for i in range(min(k, 2) + 1):  # z x (p - joint_i), dotted with n
                grad[n, k, i] = (best_px[k] - x[i]) * ny - (best_py[k] - y[i]) * nx
    return dist, grad


@kernel(nogil=True, inline='always')
def _joint_points(q, base, link_lengths, x, y):
    """Write base, elbow, wrist and wafer centre of one configuration (3,) into x, y (4,)."""
    x[0], y[0] = base[0], base[1]
    theta, cx_, cy_ = 0.0, 0.0, 0.0
    for j in range(3):  # joint points: base + cumulative link vectors
        theta += q[j]
        cx_ += link_lengths[j] * np.cos(theta)
        cy_ += link_lengths[j] * np.sin(theta)
        x[j + 1], y[j + 1] = base[0] + cx_, base[1] + cy_


@kernel(nogil=True, inline='always')
def _link_to_edge(ax, ay, bx, by, cx, cy, dx, dy, edge_len_sq, start, start_ux, start_uy):
    """
    Return the distance of link a-b to edge c-d, with the witness pair of its nearest points.

    ``start`` is the distance of the near end a to the edge (the previous link's far end)
    and (start_ux, start_uy) its offset from the edge's nearest point. Returns (gap, end,
    end_ux, end_uy, near, near_px, near_py, near_ux, near_uy): the distance (0 when the link
    crosses the edge), the far end b's distance and offset, and the nearest candidate's
    distance ``near`` (equal to ``gap``), its point p on the link and the offset u of p from
    the edge's point.
    """
    ex, ey = dx - cx, dy - cy
    # The link's far end to the edge.
    s = min(max(((bx - cx) * ex + (by - cy) * ey) / edge_len_sq, 0.0), 1.0)
    px, py = bx - cx - s * ex, by - cy - s * ey
    end = np.sqrt(px * px + py * py)
    gap = min(end, start)
    if end <= start:
        near, near_px, near_py, near_ux, near_uy = end, bx, by, px, py
    else:
        near, near_px, near_py, near_ux, near_uy = start, ax, ay, start_ux, start_uy
    # The edge's two vertices to the link.
    abx, aby = bx - ax, by - ay
    ab2 = max(abx * abx + aby * aby, 1e-300)
    for vx, vy in ((cx, cy), (dx, dy)):
        t = min(max(((vx - ax) * abx + (vy - ay) * aby) / ab2, 0.0), 1.0)
        wx, wy = vx - ax - t * abx, vy - ay - t * aby
        vertex = np.sqrt(wx * wx + wy * wy)
        gap = min(gap, vertex)
        if vertex < near:
            near, near_px, near_py, near_ux, near_uy = vertex, ax + t * abx, ay + t * aby, -wx, -wy
    side_c = abx * (cy - ay) - aby * (cx - ax)
    side_d = abx * (dy - ay) - aby * (dx - ax)
    side_a = ex * (ay - cy) - ey * (ax - cx)
    side_b = ex * (by - cy) - ey * (bx - cx)
    if side_c * side_d <= 0.0 and side_a * side_b <= 0.0:
        gap = near = 0.0
    return gap, end, px, py, near, near_px, near_py, near_ux, near_uy
