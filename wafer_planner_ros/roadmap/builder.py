"""
Adaptive PRM construction (paper section 3) with certified edges.

Nodes are added in rounds. Each round draws ``draws_per_round`` times from the sampler pool
by the adaptive weights (see ``samplers``), tries to connect each new node to its
``neighbors`` nearest earlier nodes (KD-tree) with certified edges, scores every draw and
updates the weights. When the roadmap has its nodes, every station configuration is added
and connected to its ``station_neighbors`` nearest nodes.
"""

import enum
import logging
import time

import numpy as np

from wafer_planner_ros.errors import WaferPlannerError
from wafer_planner_ros.geometry.certify import certify_segments
from wafer_planner_ros.roadmap import samplers
from wafer_planner_ros.roadmap.graph import Roadmap, RoadmapSettings
from wafer_planner_ros.roadmap.graph import SAMPLER_NAMES, STATION_SAMPLER

logger = logging.getLogger(__name__)


class Outcome(str, enum.Enum):
    """What a new node did to the roadmap; the values name its count in the statistics."""

    MERGE = 'merges'
    """Joined two or more components."""
    NEW_COMPONENT = 'new_components'
    """Connected to nothing."""
    COVERAGE = 'coverage'
    """Joined one component, farther than the redundancy radius from its nodes."""
    REDUNDANT = 'redundant'
    """Joined one component within the redundancy radius."""


BARREN_ROUNDS = 50
"""Rounds in a row without a single free sample after which the build gives up."""


class _UnionFind:
    def __init__(self, n: int):
        self.parent = list(range(n))

    def find(self, i: int) -> int:
        parent = self.parent
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    def union(self, i: int, j: int) -> None:
        self.parent[self.find(i)] = self.find(j)


class _Builder:
    def __init__(self, cell, settings: RoadmapSettings, rng):
        # The bodies' clearances and the port margins: no node or edge inside a port.
        self.model = cell.motion_model
        self.lipschitz = self.model.lipschitz
        self.settings = settings
        self.rng = rng
        lower, upper = cell.robot.limits.position.T
        self.pool = samplers.make_pool(lower, upper, settings.gaussian_sigma,
                                       settings.bridge_sigma)
        capacity = settings.nodes + sum(len(s.configs) for s in cell.stations.values())
        self.nodes = np.empty((capacity, 3))
        self.clearance = np.empty((capacity, self.model.body_count))
        self.sampler = np.empty(capacity, dtype=np.int8)
        self.count = 0
        self.edges, self.lengths = [], []
        self.components = _UnionFind(capacity)
        self.weights = np.ones(len(self.pool))
        keys = ('draws', 'nodes', 'failed', 'discarded', 'merges', 'new_components', 'coverage',
                'redundant')
        self.counts = {name: dict.fromkeys(keys, 0) for name in SAMPLER_NAMES}
        self.evaluations = 0
        self.candidates = 0
        self.rounds = 0

    def sample_round(self) -> int:
        """Draw one round, add its free samples as nodes; return how many were added."""
        s = self.settings
        choice = self.rng.choice(len(self.pool), size=s.draws_per_round,
                                 p=samplers.probabilities(self.weights))
        draws = np.bincount(choice, minlength=len(self.pool))
        rewards = np.zeros(len(self.pool))
        found_q, found_d, found_s = [], [], []
        for i, sampler in enumerate(self.pool):
            if draws[i] == 0:
                continue
            result = sampler.draw(self.rng, self.model, int(draws[i]))
            counts = self.counts[sampler.name]
            counts['draws'] += int(draws[i])
            counts['failed'] += result.failed
            rewards[i] += samplers.REWARD_FAILED * result.failed
            found_q.append(result.q)
            found_d.append(result.clearance)
            found_s.append(np.full(len(result.q), i, dtype=np.int8))
        q, d, which = np.concatenate(found_q), np.concatenate(found_d), np.concatenate(found_s)
        order = self.rng.permutation(len(q))
        for sampler_index in which[order[s.nodes - self.count:]]:  # beyond the node budget
            self.counts[SAMPLER_NAMES[sampler_index]]['discarded'] += 1
        order = order[:s.nodes - self.count]
        outcomes = self.add_nodes(q[order], d[order], which[order], s.neighbors)
        for sampler_index, outcome in zip(which[order], outcomes):
            name = SAMPLER_NAMES[sampler_index]
            self.counts[name]['nodes'] += 1
            self.counts[name][outcome.value] += 1
            rewards[sampler_index] += _REWARD[outcome]
        self.weights = samplers.update_weights(self.weights, rewards, draws.astype(float))
        self.rounds += 1
        return len(order)

    def add_nodes(self, q, d, which, neighbors: int) -> list:
        """Add nodes, connect each to its nearest earlier nodes; return each one's outcome."""
        first, m = self.count, len(q)
        if m == 0:
            return []
        # Candidates: k nearest existing nodes, plus the earlier nodes of this batch.
        k = min(neighbors, first)
        if k:
            from scipy.spatial import cKDTree  # imported when used: see graph.tree
            dist_old, index_old = cKDTree(self.nodes[:first]).query(q, k=k)
            dist_old, index_old = dist_old.reshape(m, k), index_old.reshape(m, k)
        else:
            dist_old, index_old = np.empty((m, 0)), np.empty((m, 0), dtype=int)
        dist_new = np.linalg.norm(q[:, None] - q[None], axis=-1)
        dist_new[np.triu_indices(m)] = np.inf
        dist = np.concatenate([dist_old, dist_new], axis=1)
        index = np.concatenate([index_old, np.broadcast_to(first + np.arange(m), (m, m))], axis=1)
        take = min(neighbors, dist.shape[1])
        nearest = np.argsort(dist, axis=1, kind='stable')[:, :take]
        dist = np.take_along_axis(dist, nearest, axis=1)
        index = np.take_along_axis(index, nearest, axis=1)
        valid = np.isfinite(dist)
        rows, cols = np.nonzero(valid)
        self.nodes[first:first + m], self.clearance[first:first + m] = q, d
        self.sampler[first:first + m] = which
        self.count += m
        target = index[rows, cols]
        ok, evaluations = certify_segments(self.model, self.lipschitz, q[rows],
                                           self.nodes[target], d[rows], self.clearance[target])
        self.evaluations += evaluations
        self.candidates += len(rows)
        rows, target = rows[ok], target[ok]
        self.edges.append(np.column_stack([target, first + rows]).astype(np.int32))
        self.lengths.append(np.linalg.norm(self.nodes[target] - q[rows], axis=1))
        nearest_dist = np.where(valid[:, 0], dist[:, 0], np.inf)
        return self._classify(first, rows, target, nearest_dist)

    def _classify(self, first, rows, target, nearest_dist) -> list:
        outcomes = []
        uf = self.components
        split = np.searchsorted(rows, np.arange(len(nearest_dist) + 1))
        for row in range(len(nearest_dist)):
            linked = target[split[row]:split[row + 1]]
            roots = {uf.find(int(j)) for j in linked}
            for j in linked:
                uf.union(first + row, int(j))
            if not roots:
                outcomes.append(Outcome.NEW_COMPONENT)
            elif len(roots) > 1:
                outcomes.append(Outcome.MERGE)
            elif nearest_dist[row] > self.settings.redundancy_radius:
                outcomes.append(Outcome.COVERAGE)
            else:
                outcomes.append(Outcome.REDUNDANT)
        return outcomes

    def finish(self, cell, seed: int, started: float) -> Roadmap:
        stations = {}
        for name, station in cell.stations.items():
            q = np.array([c.q for c in station.configs])
            d = self.model.body_clearance(q)
            first = self.count
            self.add_nodes(q, d, np.full(len(q), STATION_SAMPLER, np.int8),
                           self.settings.station_neighbors)
            stations[name] = tuple((int(c.elbow), first + i)
                                   for i, c in enumerate(station.configs))
        edges = np.concatenate(self.edges) if self.edges else np.empty((0, 2), np.int32)
        edges.sort(axis=1)
        lengths = np.concatenate(self.lengths) if self.lengths else np.empty(0)
        stats = {
            'samplers': {name: dict(c, weight=float(w)) for (name, c), w
                         in zip(self.counts.items(), self.weights)},
            'rounds': self.rounds,
            'candidate_edges': self.candidates,
            'clearance_evaluations': self.evaluations,
            'build_time_s': time.perf_counter() - started,
        }
        return Roadmap(nodes=self.nodes[:self.count].copy(),
                       clearance=self.clearance[:self.count].copy(),
                       sampler=self.sampler[:self.count].copy(), edges=edges, lengths=lengths,
                       stations=stations, seed=seed, settings=self.settings, stats=stats)


_REWARD = {Outcome.MERGE: samplers.REWARD_MERGE,
           Outcome.NEW_COMPONENT: samplers.REWARD_NEW_COMPONENT,
           Outcome.COVERAGE: samplers.REWARD_COVERAGE,
           Outcome.REDUNDANT: samplers.REWARD_REDUNDANT}


def build_roadmap(cell, settings: RoadmapSettings = RoadmapSettings(), seed: int = 0,
                  progress=None) -> Roadmap:
    """
    Build the roadmap of ``cell``; the same cell, settings and seed give the same roadmap.

    ``progress(nodes_done, nodes_total, edges)`` is called after every round. Raises
    WaferPlannerError when sampling finds no free configuration for a long time.
    """
    started = time.perf_counter()
    builder = _Builder(cell, settings, np.random.default_rng(seed))
    barren = 0
    while builder.count < settings.nodes:
        barren = 0 if builder.sample_round() else barren + 1
        if barren == BARREN_ROUNDS:
            raise WaferPlannerError(
                f'roadmap of {cell.name}: no free configuration in '
                f'{BARREN_ROUNDS * settings.draws_per_round} draws after {builder.count} '
                'nodes; the robot barely fits in the cell')
        if progress is not None:
            progress(builder.count, settings.nodes, sum(len(e) for e in builder.edges))
    roadmap = builder.finish(cell, seed, started)
    logger.info('built roadmap of %s: %d nodes, %d edges in %.2f s', cell.name,
                roadmap.node_count, roadmap.edge_count, roadmap.stats['build_time_s'])
    return roadmap
