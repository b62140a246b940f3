"""The adaptive PRM: size, connectivity, determinism, sampler statistics, safe edges."""

from dense_check import colliding_segments
import numpy as np
import pytest

from wafer_planner_ros.geometry.certify import certify_segments
from wafer_planner_ros.roadmap.builder import build_roadmap
from wafer_planner_ros.roadmap.graph import RoadmapSettings, SAMPLER_NAMES
from wafer_planner_ros.roadmap.samplers import W_MAX, W_MIN
from wafer_planner_ros.roadmap.search import astar, find_path


def _pairs(cell):
    ports = [n for n, s in cell.stations.items() if s.role == 'loadport']
    locks = [n for n, s in cell.stations.items() if s.role == 'loadlock']
    return [(a, b) for a in ports for b in locks] + [(b, a) for a in ports for b in locks]


def test_roadmap_size_and_density_match_the_paper(roadmap):
    assert roadmap.node_count >= 1500
    # Paper: 1500 nodes and 39,900 edges.
    assert 30_000 <= roadmap.edge_count <= 50_000
    assert len(np.unique(roadmap.edges, axis=0)) == roadmap.edge_count
    assert np.all(roadmap.edges[:, 0] < roadmap.edges[:, 1])
    assert np.allclose(roadmap.lengths, np.linalg.norm(
        roadmap.nodes[roadmap.edges[:, 1]] - roadmap.nodes[roadmap.edges[:, 0]], axis=1))


def test_all_stations_in_one_component_and_every_pair_has_a_path(cell, roadmap):
    components = set().union(*roadmap.station_component().values())
    assert len(components) == 1
    for a, b in _pairs(cell):
        for _, i in roadmap.stations[a]:
            for _, j in roadmap.stations[b]:
                found = find_path(roadmap, cell.motion_model, cell.motion_model.lipschitz,
                                  roadmap.nodes[i], roadmap.nodes[j])
                assert found.path is not None, f'no path {a} -> {b}'
                assert found.nodes[0] == i and found.nodes[-1] == j


def test_station_nodes_are_the_station_configurations(cell, roadmap):
    for name, entries in roadmap.stations.items():
        configs = {c.elbow: c.q for c in cell.stations[name].configs}
        assert sorted(e for e, _ in entries) == sorted(configs)
        for elbow, node in entries:
            assert np.array_equal(roadmap.nodes[node], configs[elbow])
            assert roadmap.sampler[node] == -1


def test_nodes_are_free_and_clearances_stored(cell, roadmap):
    fresh = cell.motion_model.body_clearance(roadmap.nodes)  # the port margins too
    assert np.array_equal(fresh, roadmap.clearance)
    assert np.all(fresh > 0)


def test_sampler_statistics_add_up(roadmap):
    samplers = roadmap.stats['samplers']
    assert list(samplers) == list(SAMPLER_NAMES)
    assert sum(s['nodes'] for s in samplers.values()) == roadmap.settings.nodes
    for name, s in samplers.items():
        assert s['draws'] == s['nodes'] + s['failed'] + s['discarded']
        assert s['nodes'] == s['merges'] + s['new_components'] + s['coverage'] + s['redundant']
        assert (roadmap.sampler == SAMPLER_NAMES.index(name)).sum() == s['nodes']
        assert W_MIN <= s['weight'] <= W_MAX
    # The rule adapts: the weights no longer all equal their start value.
    assert len({round(s['weight'], 6) for s in samplers.values()}) > 1


def test_same_seed_same_roadmap_other_seed_other_roadmap(default_cell):
    settings = RoadmapSettings(nodes=300)
    a = build_roadmap(default_cell, settings, seed=7)
    b = build_roadmap(default_cell, settings, seed=7)
    c = build_roadmap(default_cell, settings, seed=8)
    assert a.digest == b.digest
    for name, array in a.arrays().items():
        assert np.array_equal(array, b.arrays()[name]), name
    assert c.digest != a.digest


def test_progress_is_reported_until_done(default_cell):
    calls = []
    build_roadmap(default_cell, RoadmapSettings(nodes=300),
                  progress=lambda done, total, edges: calls.append((done, total, edges)))
    assert calls[-1][:2] == (300, 300)
    assert [c[0] for c in calls] == sorted(c[0] for c in calls)


def test_arbitrary_configurations_connect_at_query_time(cell, roadmap):
    rng = np.random.default_rng(41)
    model, lipschitz = cell.motion_model, cell.motion_model.lipschitz
    limits = cell.robot.limits.position
    q = rng.uniform(limits[:, 0], limits[:, 1], (200, 3))
    q = q[model.clearance(q) > 0][:20]
    goal_node = roadmap.stations[sorted(roadmap.stations)[0]][0][1]
    goal = roadmap.nodes[goal_node]
    reached = 0
    for start in q:
        found = find_path(roadmap, model, lipschitz, start, goal)
        eager = _eager_length(roadmap, model, lipschitz, start, goal_node)
        if eager is not None:  # lazy certification finds the same shortest path
            assert found.path is not None and found.length == pytest.approx(eager, rel=1e-12)
        if found.path is not None:
            reached += 1
            path = found.path
            assert np.array_equal(path[0], start) and np.array_equal(path[-1], goal)
            assert len(colliding_segments(cell.fcl_model(), path[:-1], path[1:])) == 0
    assert reached >= 18


def _eager_length(roadmap, model, lipschitz, start, goal_node):
    """Return the shortest path length when every query edge is certified first."""
    n = roadmap.node_count
    near = roadmap.tree.query(start, k=roadmap.settings.query_neighbors)[1]
    ends = np.vstack([roadmap.nodes[near], roadmap.nodes[goal_node]])
    d = model.body_clearance(start[None])
    ok, _ = certify_segments(model, lipschitz, np.broadcast_to(start, ends.shape), ends,
                             np.repeat(d, len(ends), axis=0),
                             model.body_clearance(ends))
    extra = {n: []}
    for j, good in zip(list(near) + [goal_node], ok):
        if good:
            w = float(np.linalg.norm(roadmap.nodes[j] - start))
            extra[n].append((int(j), w))
            extra.setdefault(int(j), []).append((n, w))
    found = astar(roadmap.graph, np.vstack([roadmap.nodes, start]), n, goal_node, extra)
    return None if found is None else found[1]


@pytest.mark.slow
def test_every_edge_of_the_default_roadmap_is_free_when_rechecked_densely_with_fcl(
        default_cell, default_roadmap):
    edges = default_roadmap.edges
    nodes = default_roadmap.nodes
    colliding = colliding_segments(default_cell.fcl_model(), nodes[edges[:, 0]],
                                   nodes[edges[:, 1]])
    assert len(colliding) == 0, f'{len(colliding)} edges collide, e.g. {edges[colliding[0]]}'


class _Solid:
    """A clearance model of a cell with no free space at all."""

    body_count = 4
    lipschitz = np.ones((4, 3))

    def body_clearance(self, q):
        return -np.ones((len(np.atleast_2d(q)), 4))

    def clearance(self, q):
        return -np.ones(len(np.atleast_2d(q)))


def test_build_gives_up_with_a_clear_error_when_nothing_is_free(default_cell_file):
    from wafer_planner_ros.cell.model import Cell
    from wafer_planner_ros.errors import WaferPlannerError
    cell = Cell.from_yaml(default_cell_file)
    cell.__dict__['motion_model'] = _Solid()  # a fresh cell, so no fixture is affected
    with pytest.raises(WaferPlannerError, match='no free configuration in 10000 draws'):
        build_roadmap(cell, RoadmapSettings(nodes=100))
