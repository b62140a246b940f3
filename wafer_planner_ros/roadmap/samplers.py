"""
The PRM sampler pool (paper section 3) and the adaptive weights that choose among them.

The pool holds a uniform, a Gaussian and a bridge-test sampler.
Each sampler turns a number of draws into free configurations, vectorised; a draw that
yields nothing (a uniform sample in collision, a Gaussian pair that does not straddle the
obstacle boundary, a bridge whose ends are not both in collision or whose middle is not
free) is a failed draw.

Adaptive rule (documented in doc/how-it-works.md): every sampler i has a weight w_i, initially 1,
and each draw picks sampler i with probability ``p_i = (1 - n * FLOOR) * w_i / sum(w) +
FLOOR`` so that no sampler is ever starved. After every round each draw is scored:

=========================================================  ======
outcome of the draw                                         reward
=========================================================  ======
its sample connected two or more roadmap components          +1.0
its sample could connect to nothing (a new component)        +0.5
joined one component, nearest node beyond the redundancy     +0.2
radius (added coverage)
joined one component within the redundancy radius            -0.2
(redundant)
no sample (in collision, or the sampler's test failed)       -0.2
=========================================================  ======

and ``w_i <- clip(w_i * exp(RATE * mean reward of sampler i's draws), W_MIN, W_MAX)``.
"""

from dataclasses import dataclass
from typing import Tuple

import numpy as np

FLOOR = 0.05
RATE = 1.0
W_MIN, W_MAX = 0.05, 20.0

REWARD_MERGE = 1.0
REWARD_NEW_COMPONENT = 0.5
REWARD_COVERAGE = 0.2
REWARD_REDUNDANT = -0.2
REWARD_FAILED = -0.2


@dataclass(frozen=True)
class Draws:
    """Free configurations produced by one sampler from a number of draws."""

    q: np.ndarray
    """(m, 3) free configurations."""
    clearance: np.ndarray
    """(m, B) their per-body clearances (m)."""
    failed: int
    """Draws that produced nothing."""


class Sampler:
    """Base class: draw configurations from the joint-limit box."""

    name = 'sampler'

    def __init__(self, lower: np.ndarray, upper: np.ndarray, sigma: float):
        """Sample inside [lower, upper] (rad); ``sigma`` is the sampler's spread (rad)."""
        self.lower, self.upper, self.sigma = lower, upper, sigma

    def _uniform(self, rng, n: int) -> np.ndarray:
        return rng.uniform(self.lower, self.upper, size=(n, len(self.lower)))

    def _near(self, rng, q: np.ndarray) -> np.ndarray:
        return np.clip(q + rng.normal(0.0, self.sigma, size=q.shape), self.lower, self.upper)

    def draw(self, rng, model, n: int) -> Draws:
        """Return the free configurations of ``n`` draws."""
        raise NotImplementedError


class UniformSampler(Sampler):
    """Uniform over the joint-limit box: coverage."""

    name = 'uniform'

    def draw(self, rng, model, n: int) -> Draws:
        """Return the free ones of n uniform samples."""
        q = self._uniform(rng, n)
        d = model.body_clearance(q)
        free = np.all(d > 0.0, axis=1)
        return Draws(q[free], d[free], int(n - free.sum()))


class GaussianSampler(Sampler):
    """Pairs one sigma apart that straddle the obstacle boundary: keep the free one."""

    name = 'gaussian'

    def draw(self, rng, model, n: int) -> Draws:
        """Return the free member of each pair with exactly one free member."""
        a = self._uniform(rng, n)
        b = self._near(rng, a)
        d = model.body_clearance(np.concatenate([a, b]))
        da, db = d[:n], d[n:]
        free_a, free_b = np.all(da > 0.0, axis=1), np.all(db > 0.0, axis=1)
        keep = free_a != free_b
        q = np.where(free_a[:, None], a, b)[keep]
        clearance = np.where(free_a[:, None], da, db)[keep]
        return Draws(q, clearance, int(n - keep.sum()))


class BridgeSampler(Sampler):
    """Bridge test: both ends in collision, midpoint free: narrow passages."""

    name = 'bridge'

    def draw(self, rng, model, n: int) -> Draws:
        """Return the free midpoints of bridges whose ends both collide."""
        a = self._uniform(rng, n)
        blocked = model.clearance(a) <= 0.0
        a = a[blocked]
        b = self._near(rng, a)
        blocked = model.clearance(b) <= 0.0
        mid = 0.5 * (a[blocked] + b[blocked])
        d = model.body_clearance(mid)
        free = np.all(d > 0.0, axis=1)
        return Draws(mid[free], d[free], int(n - free.sum()))


def make_pool(lower, upper, gaussian_sigma: float, bridge_sigma: float) -> Tuple[Sampler, ...]:
    """Return the sampler pool in a fixed order (the order of the statistics)."""
    return (UniformSampler(lower, upper, 0.0), GaussianSampler(lower, upper, gaussian_sigma),
            BridgeSampler(lower, upper, bridge_sigma))


def probabilities(weights: np.ndarray) -> np.ndarray:
    """Return the draw probabilities of the samplers for the given weights."""
    n = len(weights)
    return (1.0 - n * FLOOR) * weights / weights.sum() + FLOOR


def update_weights(weights: np.ndarray, reward_sums: np.ndarray, draws: np.ndarray):
    """Return the weights after a round, given each sampler's summed rewards and draws."""
    mean = np.divide(reward_sums, draws, out=np.zeros_like(reward_sums), where=draws > 0)
    return np.clip(weights * np.exp(RATE * mean), W_MIN, W_MAX)
