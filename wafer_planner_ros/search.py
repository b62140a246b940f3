"""A* over the roadmap (paper section 3): the shortest path in joint-space length."""

from collections import defaultdict
import heapq
from typing import Mapping, Optional, Sequence, Tuple

import numpy as np
from scipy.sparse import csr_matrix

from wafer_planner_ros.certify import certify_segments


def astar(graph: csr_matrix, coords: np.ndarray, start: int, goal: int,
          extra: Optional[Mapping[int, Sequence[Tuple[int, float]]]] = None):
    """
    Return ``(path, length)``: the shortest node sequence from start to goal, or None.

    ``graph`` is a symmetric adjacency matrix of edge lengths between ``coords`` (N, 3);
    the heuristic, the straight-line distance to the goal, is consistent for such edges, so
    the first time the goal is taken from the queue its path is optimal. ``extra`` adds
    edges for nodes beyond the matrix (index >= N, e.g. query configurations appended to
    ``coords``): node -> [(neighbour, length), ...], listed in both directions.
    """
    extra = extra or {}
    indptr, indices, weights = graph.indptr, graph.indices, graph.data
    n_graph = graph.shape[0]
    heuristic = np.linalg.norm(coords - coords[goal], axis=1)
    cost = np.full(len(coords), np.inf)
    parent = np.full(len(coords), -1)
    closed = np.zeros(len(coords), dtype=bool)
    cost[start] = 0.0
    queue = [(heuristic[start], start)]
    while queue:
        _, node = heapq.heappop(queue)
        if closed[node]:
            continue
        if node == goal:
            return _unwind(parent, goal), float(cost[goal])
        closed[node] = True
        if node < n_graph:
            lo, hi = indptr[node], indptr[node + 1]
            neighbours, lengths = indices[lo:hi], weights[lo:hi]
        else:
            neighbours, lengths = np.empty(0, dtype=int), np.empty(0)
        links = extra.get(node)
        if links:
            neighbours = np.concatenate([neighbours, [v for v, _ in links]]).astype(int)
            lengths = np.concatenate([lengths, [w for _, w in links]])
        candidate = cost[node] + lengths
        better = candidate < cost[neighbours]
        neighbours, candidate = neighbours[better], candidate[better]
        cost[neighbours] = candidate
        parent[neighbours] = node
        for v, f in zip(neighbours.tolist(), (candidate + heuristic[neighbours]).tolist()):
            heapq.heappush(queue, (f, v))
    return None


def _unwind(parent: np.ndarray, goal: int) -> list:
    path = [goal]
    while parent[path[-1]] >= 0:
        path.append(int(parent[path[-1]]))
    return path[::-1]


def find_path(roadmap, model, lipschitz: np.ndarray, start: np.ndarray, goal: np.ndarray,
              clock=None, neighbors=None):
    """
    Return the shortest roadmap path between two free configurations, or None.

    A configuration that is a roadmap node (a station) is used as that node; any other is
    connected at query time with certified edges to its ``neighbors`` nearest nodes (first
    ``query_neighbors``, then ``station_neighbors`` if that finds no path), and a certified
    straight line from start to goal is also a candidate. Returns ``(configurations (P, 3),
    node indices (-1 for query configurations), length)``. ``clock.lap(stage)`` is called
    after the 'connect' and 'search' stages when a clock is given.
    """
    n = roadmap.node_count
    ends = [np.asarray(start, float), np.asarray(goal, float)]
    index, extra = [], defaultdict(list)
    for virtual, q in zip((n, n + 1), ends):
        distance, nearest = roadmap.tree.query(q)
        if distance == 0.0:
            index.append(int(nearest))
            continue
        index.append(virtual)
        nodes, lengths = roadmap.connect(model, lipschitz, q,
                                         neighbors or roadmap.settings.query_neighbors)
        for j, w in zip(nodes.tolist(), lengths.tolist()):
            extra[virtual].append((j, w))
            extra[j].append((virtual, w))
    if index[0] >= n or index[1] >= n:
        d = model.body_clearance(np.stack(ends))
        ok, _ = certify_segments(model, lipschitz, ends[0][None], ends[1][None], d[:1], d[1:])
        if ok[0]:
            w = float(np.linalg.norm(ends[1] - ends[0]))
            extra[index[0]].append((index[1], w))
            extra[index[1]].append((index[0], w))
    coords = np.vstack([roadmap.nodes] + ends)
    if clock is not None:
        clock.lap('connect')
    found = astar(roadmap.graph, coords, index[0], index[1], extra)
    if clock is not None:
        clock.lap('search')
    wider = roadmap.settings.station_neighbors
    if found is None and max(index) >= n and (neighbors or 0) < wider:
        return find_path(roadmap, model, lipschitz, start, goal, clock, wider)
    if found is None:
        return None
    path, length = found
    path = np.array(path)
    return coords[path], np.where(path < n, path, -1), length
