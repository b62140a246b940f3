"""
A one-dimensional motion of constant-jerk phases: sigma(t) and its first three derivatives.

The timing of a motion along a fixed path (a channel through a port, ``moves.timing``; the
path a controlled stop keeps, ``trajectory.retimed``) is one number moving in time: each
phase has a constant jerk, so sigma is a cubic in time on it, fixed by the state (sigma,
sigma', sigma'') at the phase's start. ``JerkProfile`` holds the phases' start times, their
jerks and those states, evaluates them, and bounds the speed exactly (a quadratic per
phase: its extreme is at an end or where the acceleration is zero).
"""

from dataclasses import dataclass
from typing import Mapping, Optional

import numpy as np

JOIN_TOLERANCE = 1e-9
"""How far a phase's state may end from the next one's start (rounding)."""


@dataclass(frozen=True, eq=False)
class JerkProfile:
    """sigma(t) of N constant-jerk phases, from its first state at t = 0."""

    starts: np.ndarray
    """(N + 1,) the phases' start times, then the end time (s)."""
    jerks: np.ndarray
    """(N,) each phase's jerk."""
    states: np.ndarray
    """(N + 1, 3) sigma, its speed and acceleration at each start, then at the end."""

    @property
    def duration(self) -> float:
        """Return the profile's time (s)."""
        return float(self.starts[-1])

    @property
    def end_speed(self) -> float:
        """Return the speed at the end."""
        return float(self.states[-1, 1])

    @property
    def end_acceleration(self) -> float:
        """Return the acceleration at the end."""
        return float(self.states[-1, 2])

    def evaluate(self, t) -> np.ndarray:
        """Return (K, 4): sigma and its first three derivatives at times ``t`` (clipped)."""
        t = np.clip(np.atleast_1d(np.asarray(t, float)), 0.0, self.duration)
        k = np.clip(np.searchsorted(self.starts, t, side='right') - 1, 0, len(self.jerks) - 1)
        tau = t - self.starts[k]
        (p, v, a), j = self.states[k].T, self.jerks[k]
        out = np.stack([p + tau * (v + tau * (a / 2.0 + tau * j / 6.0)),
                        v + tau * (a + tau * j / 2.0), a + tau * j, j], axis=1)
        at_end = t >= self.duration
        out[at_end, :3] = self.states[-1]
        return out

    def peak_speed(self, a, b) -> np.ndarray:
        """Return the exact largest |sigma'| on each [a_k, b_k] within one phase, (K,)."""
        a, b = np.atleast_1d(np.asarray(a, float)), np.atleast_1d(np.asarray(b, float))
        k = np.clip(np.searchsorted(self.starts, 0.5 * (a + b), side='right') - 1, 0,
                    len(self.jerks) - 1)
        (_, v, acc), j = self.states[k].T, self.jerks[k]

        def speed(tau):
            return np.abs(v + tau * (acc + tau * j / 2.0))

        low, high = a - self.starts[k], b - self.starts[k]
        peaks = np.maximum(speed(low), speed(high))
        with np.errstate(divide='ignore', invalid='ignore'):
            turn = np.where(j != 0.0, -acc / j, -np.inf)
        inside = (turn > low) & (turn < high)
        return np.where(inside, np.maximum(peaks, speed(np.where(inside, turn, low))), peaks)

    def turns(self) -> np.ndarray:
        """
        Return times between which sigma'' keeps its sign, so sigma' is monotone (ascending).

        sigma'' is continuous and linear on each phase: it changes sign only where it is
        zero, inside a phase or at a phase's start; all those times are returned.
        """
        tau = np.diff(self.starts)
        a, j = self.states[:-1, 2], self.jerks
        with np.errstate(divide='ignore', invalid='ignore'):
            inner = np.where(j != 0.0, -a / j, -1.0)
        within = (inner > 0.0) & (inner < tau)
        at_start = self.states[1:-1, 2] == 0.0
        return np.unique(np.concatenate([self.starts[:-1][within] + inner[within],
                                         self.starts[1:-1][at_start]]))

    def slowest(self) -> float:
        """Return the least sigma' over the profile (exact: each phase's ends and turn)."""
        tau = np.diff(self.starts)
        (_, v, a), j = self.states[:-1].T, self.jerks
        with np.errstate(divide='ignore', invalid='ignore'):
            turn = np.where(j != 0.0, -a / j, -1.0)
        turn = np.where((turn > 0.0) & (turn < tau), turn, 0.0)
        at_turn = v + turn * (a + turn * j / 2.0)
        return float(min(self.states[:, 1].min(), at_turn.min()))

    def describe(self) -> dict:
        """Return the profile as plain data."""
        return {'starts': self.starts.tolist(), 'jerks': self.jerks.tolist(),
                'states': self.states.tolist()}

    @classmethod
    def described(cls, data: Mapping) -> 'JerkProfile':
        """Return the profile ``describe`` gave (raise ValueError if it is not one)."""
        try:
            made = cls(*(np.asarray(data[k], float) for k in ('starts', 'jerks', 'states')))
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f'not a profile: {exc}') from None
        phases = len(made.jerks) if made.jerks.ndim == 1 else -1
        if phases < 1 or made.starts.shape != (phases + 1,) or \
                made.states.shape != (phases + 1, 3):
            raise ValueError(f'a profile with shapes {made.starts.shape}, '
                             f'{made.jerks.shape}, {made.states.shape}')
        return made

    def structure_problem(self) -> Optional[str]:
        """Return what makes the data no motion of joined phases from t = 0, or None."""
        if not (np.isfinite(self.starts).all() and np.isfinite(self.jerks).all()
                and np.isfinite(self.states).all()):
            return 'its data are not finite'
        if self.starts[0] != 0.0 or np.any(np.diff(self.starts) < 0.0):
            return f'its phase times {self.starts.tolist()} do not ascend from 0'
        # Each phase must end where the next starts (its cubic integrated).
        tau = np.diff(self.starts)
        p, v, a = self.states[:-1].T
        j = self.jerks
        integrated = np.stack([p + tau * (v + tau * (a / 2.0 + tau * j / 6.0)),
                               v + tau * (a + tau * j / 2.0), a + tau * j], axis=1)
        gap = np.abs(integrated - self.states[1:]).max()
        if not gap <= JOIN_TOLERANCE:
            return f'its phases do not join (by {gap:.3g})'
        return None
