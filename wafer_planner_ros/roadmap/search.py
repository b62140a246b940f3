"""A* over the roadmap (paper section 3): the shortest path in joint-space length."""

from collections import defaultdict
from dataclasses import dataclass
import time
from typing import Mapping, Optional, Sequence, Tuple

import numpy as np

from wafer_planner_ros.geometry.certify import certify_segments
from wafer_planner_ros.kernels import kernel


def astar(graph: 'scipy.sparse.csr_matrix', coords: np.ndarray, start: int,  # noqa: F821
          goal: int, extra: Optional[Mapping[int, Sequence[Tuple[int, float]]]] = None):
    """
    Return ``(path, length)``: the shortest node sequence from start to goal, or None.

    ``graph`` is a symmetric adjacency matrix of edge lengths between ``coords`` (N, 3);
    the heuristic, the straight-line distance to the goal, is consistent for such edges, so
    the first time the goal is taken from the queue its path is optimal. ``extra`` adds
    edges for nodes beyond the matrix (index >= N, e.g. query configurations appended to
    ``coords``): node -> [(neighbour, length), ...], listed in both directions. The search
    itself is compiled (``_astar``); ties in the queue go to the lower node index.
    """
    links = [(u, v, w) for u, pairs in (extra or {}).items() for v, w in pairs]
    source = np.array([u for u, _, _ in links], dtype=np.int64)
    order = np.argsort(source, kind='stable')
    extra_ptr = np.zeros(len(coords) + 1, dtype=np.int64)
    np.cumsum(np.bincount(source, minlength=len(coords)), out=extra_ptr[1:])
    extra_to = np.array([v for _, v, _ in links], dtype=np.int64)[order]
    extra_w = np.array([w for _, _, w in links], dtype=float)[order]
    found, parent, length = _astar(graph.indptr.astype(np.int64),
                                   graph.indices.astype(np.int64), graph.data,
                                   graph.shape[0], extra_ptr, extra_to, extra_w,
                                   np.ascontiguousarray(coords, float), start, goal)
    return (_unwind(parent, goal), float(length)) if found else None


def _unwind(parent: np.ndarray, goal: int) -> list:
    path = [goal]
    while parent[path[-1]] >= 0:
        path.append(int(parent[path[-1]]))
    return path[::-1]


@kernel(nogil=True)
def _astar(indptr, indices, weights, n_graph, extra_ptr, extra_to, extra_w, coords, start,
           goal):
    """Return (found, parent (N,), cost of the goal): A* with a binary heap of (f, node)."""
    n = len(coords)
    heuristic = np.empty(n)
    for i in range(n):
        heuristic[i] = np.sqrt(np.sum((coords[i] - coords[goal]) ** 2))
    cost = np.full(n, np.inf)
    parent = np.full(n, -1, dtype=np.int64)
    closed = np.zeros(n, dtype=np.bool_)
    capacity = len(indices) + len(extra_to) + 1
    keys, nodes = np.empty(capacity), np.empty(capacity, dtype=np.int64)
    cost[start] = 0.0
    keys[0], nodes[0], size = heuristic[start], start, 1
    while size > 0:
        node = nodes[0]
        size -= 1
        keys[0], nodes[0] = keys[size], nodes[size]
        _sift_down(keys, nodes, size)
        if closed[node]:
            continue
        if node == goal:
            return True, parent, cost[goal]
        closed[node] = True
        if node < n_graph:
            size = _relax(node, indptr[node], indptr[node + 1], indices, weights, cost,
                          parent, heuristic, keys, nodes, size)
        size = _relax(node, extra_ptr[node], extra_ptr[node + 1], extra_to, extra_w, cost,
                      parent, heuristic, keys, nodes, size)
    return False, parent, np.inf


@kernel(nogil=True)
def _relax(node, lo, hi, to, weights, cost, parent, heuristic, keys, nodes, size):
    """Relax the edges node -> to[lo:hi]; push what improved; return the heap size."""
    for e in range(lo, hi):
        v, candidate = to[e], cost[node] + weights[e]
        if candidate < cost[v]:
            cost[v], parent[v] = candidate, node
            keys[size], nodes[size] = candidate + heuristic[v], v
            _sift_up(keys, nodes, size)
            size += 1
    return size


@kernel(nogil=True)
def _before(keys, nodes, a, b):
    return keys[a] < keys[b] or (keys[a] == keys[b] and nodes[a] < nodes[b])


@kernel(nogil=True)
def _sift_up(keys, nodes, i):
    while i > 0:
        up = (i - 1) // 2
        if not _before(keys, nodes, i, up):
            break
        keys[i], keys[up] = keys[up], keys[i]
        nodes[i], nodes[up] = nodes[up], nodes[i]
        i = up


@kernel(nogil=True)
def _sift_down(keys, nodes, size):
    i = 0
    while True:
        child = 2 * i + 1
        if child >= size:
            break
        if child + 1 < size and _before(keys, nodes, child + 1, child):
            child += 1
        if not _before(keys, nodes, child, i):
            break
        keys[i], keys[child] = keys[child], keys[i]
        nodes[i], nodes[child] = nodes[child], nodes[i]
        i = child


@dataclass(frozen=True, eq=False)
class Route:
    """What a query found: the path, or None, and where the time went."""

    path: Optional[np.ndarray]
    """(P, 3) configurations from start to goal; None when there is no path."""
    nodes: Optional[np.ndarray]
    """(P,) roadmap node indices, -1 for query configurations."""
    length: float
    """Joint-space length of the path (inf without one)."""
    connect_ms: float
    """Connecting the query configurations: neighbours and edge certification."""
    search_ms: float
    """A* itself."""


def find_path(roadmap, model, lipschitz: np.ndarray, start: np.ndarray,
              goal: np.ndarray) -> Route:
    """
    Return the shortest roadmap path between two free configurations.

    A configuration that is a roadmap node (a station) is used as that node; any other is
    connected at query time to its nearest nodes (first ``query_neighbors``, then
    ``station_neighbors`` if that finds no path), and the straight line from start to goal
    is also a candidate. These query edges are certified lazily (as in Lazy PRM): A* runs
    with all of them, then the ones on the path found are certified; when one fails, every
    remaining query edge of that configuration is certified at once and A* runs again. The
    answer is the same shortest path over certified edges as certifying them all first,
    usually for two certifications instead of forty.
    """
    spent = [0.0, 0.0, time.perf_counter()]  # connect, search (ms), last instant
    found = None
    for neighbors in (roadmap.settings.query_neighbors, roadmap.settings.station_neighbors):
        found, queried = _search(roadmap, model, lipschitz, start, goal, neighbors, spent)
        if found is not None or not queried:
            break
    if found is None:
        return Route(None, None, np.inf, spent[0], spent[1])
    path, length = found
    path = np.array(path)
    coords = np.vstack([roadmap.nodes, start, goal])
    n = roadmap.node_count
    return Route(coords[path], np.where(path < n, path, -1), length, spent[0], spent[1])


def _search(roadmap, model, lipschitz, start, goal, neighbors: int, spent: list) -> tuple:
    """Return (A*'s (path, length) or None, whether an end is a query configuration)."""
    n = roadmap.node_count
    ends = [np.asarray(start, float), np.asarray(goal, float)]
    clearance = model.body_clearance(np.stack(ends))
    coords = np.vstack([roadmap.nodes] + ends)
    body_clearance = np.vstack([roadmap.clearance, clearance])
    index, extra, pending = [], defaultdict(list), {}
    for virtual, q in zip((n, n + 1), ends):
        distance, nearest = roadmap.tree.query(q)
        if distance == 0.0:
            index.append(int(nearest))
            continue
        index.append(virtual)
        nodes = np.atleast_1d(roadmap.tree.query(q, k=min(neighbors, n))[1])
        for j in nodes.tolist():
            _link(extra, pending, coords, virtual, j)
    if index[0] >= n or index[1] >= n:
        _link(extra, pending, coords, index[0], index[1])
    _lap(spent, 0)
    while True:
        found = astar(roadmap.graph, coords, index[0], index[1], extra)
        _lap(spent, 1)
        if found is None:
            break
        unchecked = [edge for edge in zip(found[0][:-1], found[0][1:])
                     if tuple(sorted(edge)) in pending]
        if not unchecked:
            break
        failed = _certify(model, lipschitz, coords, body_clearance, extra, pending, unchecked)
        # A configuration whose nearest edge failed likely has more that fail: check them all.
        rest = [edge for edge in pending if set(edge) & failed]
        if rest:
            _certify(model, lipschitz, coords, body_clearance, extra, pending, rest)
        _lap(spent, 0)
    return found, max(index) >= n


def _lap(spent: list, phase: int) -> None:
    """Add the milliseconds since the last lap to ``spent[phase]``."""
    now = time.perf_counter()
    spent[phase] += (now - spent[2]) * 1000.0
    spent[2] = now


def _link(extra, pending, coords, a: int, b: int) -> None:
    """Add the not yet certified edge a-b (both directions) with its joint-space length."""
    w = float(np.linalg.norm(coords[b] - coords[a]))
    extra[a].append((b, w))
    extra[b].append((a, w))
    pending[tuple(sorted((a, b)))] = w


def _certify(model, lipschitz, coords, clearance, extra, pending, edges) -> set:
    """Certify edges; drop those that fail from ``extra``; return their query-end nodes."""
    a, b = np.array(edges).T
    ok, _ = certify_segments(model, lipschitz, coords[a], coords[b], clearance[a],
                             clearance[b])
    failed = set()
    for u, v, good in zip(a.tolist(), b.tolist(), ok.tolist()):
        del pending[tuple(sorted((u, v)))]
        if not good:
            extra[u] = [link for link in extra[u] if link[0] != v]
            extra[v] = [link for link in extra[v] if link[0] != u]
            failed.update(w for w in (u, v) if w >= len(clearance) - 2)
    return failed
