"""A* against scipy's Dijkstra on the same graph."""

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from wafer_planner_ros.roadmap.search import astar


def test_astar_length_equals_dijkstra_for_many_random_pairs(roadmap):
    rng = np.random.default_rng(51)
    pairs = rng.integers(0, roadmap.node_count, (300, 2))
    distances = dijkstra(roadmap.graph, indices=np.unique(pairs[:, 0]))
    row = {int(s): i for i, s in enumerate(np.unique(pairs[:, 0]))}
    for start, goal in pairs:
        expected = distances[row[int(start)], goal]
        found = astar(roadmap.graph, roadmap.nodes, int(start), int(goal))
        if np.isinf(expected):
            assert found is None
            continue
        path, length = found
        assert np.isclose(length, expected, rtol=1e-12, atol=1e-12)
        assert path[0] == start and path[-1] == goal
        steps = np.asarray(roadmap.graph[path[:-1], path[1:]]).ravel()
        assert np.all(steps > 0) and np.isclose(steps.sum(), length)


def test_astar_takes_the_detour_when_the_direct_edge_is_longer():
    coords = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0], [1, 1, 0]])
    # 0-2 directly costs 5 (an edge can be longer than the straight distance only in this toy
    # graph; it keeps the heuristic admissible), 0-1-2 costs 2, 0-3-2 costs ~2.83.
    i = [0, 0, 1, 0, 3]
    j = [2, 1, 2, 3, 2]
    w = [5.0, 1.0, 1.0, np.sqrt(2), np.sqrt(2)]
    graph = csr_matrix((w + w, (i + j, j + i)), shape=(4, 4))
    assert astar(graph, coords, 0, 2) == ([0, 1, 2], 2.0)


def test_astar_reports_no_path_between_components():
    coords = np.array([[0.0, 0, 0], [1, 0, 0], [5, 0, 0]])
    graph = csr_matrix(([1.0, 1.0], ([0, 1], [1, 0])), shape=(3, 3))
    assert astar(graph, coords, 0, 2) is None


def test_extra_edges_join_query_nodes():
    coords = np.array([[0.0, 0, 0], [1, 0, 0], [-1, 0, 0], [2, 0, 0]])
    graph = csr_matrix(([1.0, 1.0], ([0, 1], [1, 0])), shape=(2, 2))
    extra = {2: [(0, 1.0)], 0: [(2, 1.0)], 3: [(1, 1.0)], 1: [(3, 1.0)]}
    assert astar(graph, coords, 2, 3, extra) == ([2, 0, 1, 3], 3.0)
