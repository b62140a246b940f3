"""The roadmap: free configurations joined by certified straight edges in joint space."""

from dataclasses import asdict, dataclass, field
import functools
import hashlib
import json
from typing import Mapping, Tuple

import numpy as np


SAMPLER_NAMES = ('uniform', 'gaussian', 'bridge')
STATION_SAMPLER = -1  # sampler index stored for station nodes


MAX_NODES = 200000
"""The largest roadmap (millions of edges and gigabytes of memory while it is built)."""
MAX_SEED = 2 ** 31 - 1
"""Seeds are 0 to this (a ROS integer parameter holds them)."""


def check_seed(seed) -> int:
    """Return ``seed`` when it is an integer in [0, MAX_SEED]; raise ValueError otherwise."""
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed <= MAX_SEED:
        raise ValueError(f'the seed must be an integer in [0, {MAX_SEED}], got {seed!r}'[:300])
    return seed


@dataclass(frozen=True)
class RoadmapSettings:
    """How a roadmap is built; part of the cache key."""

    nodes: int = 1500
    """Sampled nodes (stations are added on top)."""
    neighbors: int = 30
    """Nearest earlier nodes each new node tries to connect to (30: ~40,000 edges, paper)."""
    station_neighbors: int = 80
    """Nearest nodes a station tries to connect to (and a query configuration, at most)."""
    query_neighbors: int = 20
    """Nearest nodes a query configuration tries first."""
    gaussian_sigma: float = 0.15
    """Spread of the Gaussian sampler's second sample (rad)."""
    bridge_sigma: float = 0.5
    """Spread of the bridge test's second end (rad)."""
    draws_per_round: int = 200
    """Sampler draws between weight updates."""
    redundancy_radius: float = 0.1
    """A sample this close (rad) to a node of the component it joins is redundant."""

    def __post_init__(self):
        """Reject settings that cannot build a roadmap."""
        for name in ('nodes', 'neighbors', 'station_neighbors', 'query_neighbors',
                     'draws_per_round'):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f'roadmap setting {name} must be a positive integer, '
                                 f'got {value!r}')
        if self.nodes > MAX_NODES:
            raise ValueError(f'roadmap setting nodes must be at most {MAX_NODES}, got '
                             f'{self.nodes}')
        for name in ('gaussian_sigma', 'bridge_sigma', 'redundancy_radius'):
            if not getattr(self, name) > 0:
                raise ValueError(
                    f'roadmap setting {name} must be > 0, got {getattr(self, name)!r}')


@dataclass(frozen=True, eq=False)
class Roadmap:
    """A built roadmap. Arrays are read-only; edges are stored once with i < j."""

    nodes: np.ndarray
    """(N, 3) configurations (rad)."""
    clearance: np.ndarray
    """(N, B) per-body clearance of each node (m)."""
    sampler: np.ndarray
    """(N,) index into SAMPLER_NAMES, or STATION_SAMPLER."""
    edges: np.ndarray
    """(M, 2) node indices."""
    lengths: np.ndarray
    """(M,) joint-space length of each edge (rad)."""
    stations: Mapping[str, Tuple[Tuple[int, int], ...]]
    """Station name -> ((elbow, node index), ...)."""
    seed: int
    settings: RoadmapSettings
    stats: Mapping = field(default_factory=dict)
    """Build statistics (per-sampler counts, timings) as plain data."""

    def __post_init__(self):
        """Freeze the arrays."""
        for name in ('nodes', 'clearance', 'sampler', 'edges', 'lengths'):
            getattr(self, name).flags.writeable = False

    @property
    def node_count(self) -> int:
        """Return the number of nodes."""
        return len(self.nodes)

    @property
    def edge_count(self) -> int:
        """Return the number of edges."""
        return len(self.edges)

    @functools.cached_property
    def graph(self) -> 'csr_matrix':  # noqa: F821 - scipy: imported when used (slow)
        """Return the symmetric adjacency matrix weighted by edge length."""
        from scipy.sparse import csr_matrix
        i, j = self.edges[:, 0], self.edges[:, 1]
        n = self.node_count
        return csr_matrix((np.concatenate([self.lengths, self.lengths]),
                           (np.concatenate([i, j]), np.concatenate([j, i]))), shape=(n, n))

    @functools.cached_property
    def components(self) -> np.ndarray:
        """Return the connected-component label of every node."""
        from scipy.sparse.csgraph import connected_components
        return connected_components(self.graph, directed=False)[1]

    @functools.cached_property
    def tree(self) -> 'cKDTree':  # noqa: F821
        """Return a KD-tree over the nodes."""
        from scipy.spatial import cKDTree
        return cKDTree(self.nodes)

    @functools.cached_property
    def digest(self) -> str:
        """Return the SHA-256 of the roadmap's content (nodes, edges, stations, seed)."""
        h = hashlib.sha256()
        for name, array in self.arrays().items():
            h.update(name.encode())
            h.update(np.ascontiguousarray(array).tobytes())
        h.update(json.dumps({'stations': self.stations, 'seed': self.seed,
                             'settings': asdict(self.settings)}, sort_keys=True).encode())
        return h.hexdigest()

    def arrays(self) -> dict:
        """Return the roadmap's arrays by name (for hashing and saving)."""
        return {'nodes': self.nodes, 'clearance': self.clearance, 'sampler': self.sampler,
                'edges': self.edges, 'lengths': self.lengths}

    def station_component(self) -> dict:
        """Return, per station, the set of components its nodes lie in."""
        return {name: {int(self.components[node]) for _, node in entries}
                for name, entries in self.stations.items()}


def import_for_searches() -> None:
    """
    Import what the roadmap's searches import when first used (scipy's trees and graphs).

    Imports slow enough to notice, left to their first use so that a tool that never plans
    does not pay them: the node's processes do them once ready, so that the first requests
    find them done (with numba loaded from its cache instead of the build ahead of time,
    numba has imported much of scipy already).
    """
    import scipy.sparse.csgraph  # noqa: F401
    import scipy.spatial  # noqa: F401
