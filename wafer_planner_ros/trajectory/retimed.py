"""
A curve played along another's path with a timing of its own: q(t) = base(sigma(t)).

A controlled stop (``trajectory.stopping``) keeps the path the robot is on and changes only
how fast it is followed: sigma, the base curve's own time, runs by a ``JerkProfile`` from
where the stop begins (sigma = the moment, sigma' = 1, sigma'' = 0: exactly the base's state
there) down to sigma' = 0. ``Retimed`` is that motion as a ``Trajectory``: its derivatives
by the chain rule (``along``) from the base's, its pieces where either the timing changes
phase or sigma crosses one of the base's breaks, and each piece's joint speed bounded by the
base's exact peak over the stretch of path times the timing's exact peak speed. Unlike
the other kinds it starts in motion (the base's state at the moment) and ends at rest.
"""

from typing import ClassVar, Mapping, Optional, Sequence

import numpy as np

from wafer_planner_ros.trajectory.curve import Trajectory
from wafer_planner_ros.trajectory.jerk_profile import JerkProfile

BACKWARDS = 1e-12
"""The most sigma' may fall below 0 (rounding at the stop)."""
CROSSING_HALVINGS = 60
"""Halvings that find the time sigma crosses one of the base's breaks."""


def along(derivatives: Sequence[np.ndarray], sigma: np.ndarray,
          orders: Sequence[int]) -> list:
    """
    Return q and its time derivatives of ``orders`` along a path timed by sigma(t).

    ``derivatives``: the path's g, g', g'', g''' by its parameter at sigma (each (K, J));
    ``sigma``: (K, 4) sigma and its first three time derivatives. The chain rule:
    q' = g' s1, q'' = g'' s1^2 + g' s2, q''' = g''' s1^3 + 3 g'' s1 s2 + g' s3.
    """
    g0, g1, g2, g3 = derivatives
    s1, s2, s3 = (sigma[:, k, None] for k in (1, 2, 3))
    by_order = {0: lambda: g0, 1: lambda: g1 * s1, 2: lambda: g2 * s1 ** 2 + g1 * s2,
                3: lambda: g3 * s1 ** 3 + 3.0 * g2 * s1 * s2 + g1 * s3}
    return [by_order[k]() for k in orders]


class Retimed(Trajectory):
    """base(sigma(t)): the base curve's path under the timing sigma (the module)."""

    kind: ClassVar[str] = 'retimed'

    def __init__(self, base: Trajectory, timing: JerkProfile,
                 breaks: Optional[np.ndarray] = None):
        """
        Keep the base curve and the timing of its time sigma.

        ``breaks``: what ``breaks`` returns, where the caller has it from a curve this one
        is made of (``stopping.followed``); found at the first call otherwise, then kept.
        """
        self.base, self.timing, self._breaks = base, timing, breaks

    @property
    def duration(self) -> float:
        """Return the total time (s)."""
        return self.timing.duration

    def evaluate_orders(self, t, orders=(0, 1, 2)) -> tuple:
        """Return the derivatives of the given orders at times t, each (len(t), J)."""
        sigma = self.timing.evaluate(t)
        # A contiguous copy: the base's kernels then run the same compiled code as for any
        # other times (a strided column may take another build, rounded differently).
        derivatives = self.base.evaluate_orders(np.ascontiguousarray(sigma[:, 0]), range(4))
        return tuple(along(derivatives, sigma, orders))

    def breaks(self) -> np.ndarray:
        """
        Return 0, T, the times sigma crosses a base break and those sigma' turns.

        Between two of them the base is one of its pieces and sigma' is monotone
        (``JerkProfile.turns``), which is what ``peak_speed`` needs: a stop's timing of
        hundreds of short phases is a few pieces to prove.
        """
        if self._breaks is None:
            self._breaks = self._found_breaks()
        return self._breaks

    def _found_breaks(self) -> np.ndarray:
        """Return ``breaks`` from the base's and the timing (crossings by halving)."""
        timing = self.timing
        states, starts = timing.states, timing.starts
        base = self.base.breaks()
        inside = base[(base > states[0, 0]) & (base < states[-1, 0])]
        crossings = np.empty(0)
        if len(inside):
            # sigma never decreases: the phase holding each crossing, then halving within it.
            phase = np.clip(np.searchsorted(states[:, 0], inside, side='right') - 1, 0,
                            len(timing.jerks) - 1)
            low, high = starts[phase].copy(), starts[phase + 1].copy()
            (p, v, a), j = states[phase].T, timing.jerks[phase]
            for _ in range(CROSSING_HALVINGS):
                middle = 0.5 * (low + high)
                # sigma at ``middle``, within the phase: as ``JerkProfile.evaluate`` has it.
                tau = middle - starts[phase]
                below = p + tau * (v + tau * (a / 2.0 + tau * j / 6.0)) < inside
                low, high = np.where(below, middle, low), np.where(below, high, middle)
            crossings = high
        return np.unique(np.concatenate([[0.0, self.duration], timing.turns(), crossings]))

    def peak_speed(self, a, b) -> np.ndarray:
        """
        Return a bound of every |q'_j| on each [a_k, b_k] within one piece, (K, J).

        The base's exact largest |g'_j| over the stretch of path [sigma(a), sigma(b)]
        times the largest sigma' on [a, b], exact: sigma' is monotone within a piece, so
        it is the larger of its ends'. What the proof and the verification's collision
        steps need.
        """
        a, b = np.atleast_1d(np.asarray(a, float)), np.atleast_1d(np.asarray(b, float))
        sigma = self.timing.evaluate(np.concatenate([a, b]))
        k = len(a)
        speed = np.maximum(np.abs(sigma[:k, 1]), np.abs(sigma[k:, 1]))
        return self.base.peak_speed(np.ascontiguousarray(sigma[:k, 0]),
                                    np.ascontiguousarray(sigma[k:, 0])) * speed[:, None]

    def ill_formed(self, start: np.ndarray, goal: np.ndarray) -> Optional[str]:
        """
        Return what makes this no motion along its base from ``start`` to rest at ``goal``.

        The base well formed between its own ends; the timing's phases joined, sigma never
        moving back and staying on the base's time; exactly at ``start`` and ``goal``; at
        rest at the end (sigma' and sigma'' zero, or the base's own end reached, where it
        rests). The motion it starts in is the caller's to compare (``verify``).
        """
        ends = self.base.evaluate([0.0, self.base.duration], 0)
        problem = self.base.ill_formed(ends[0], ends[1])
        if problem is not None:
            return f'its base: {problem}'
        return self.timing_problem() or self.ends_problem(start, goal)

    def timing_problem(self) -> Optional[str]:
        """
        Return what makes the timing no motion along the base to rest, or None.

        ``ill_formed`` without the base's own form and the ends: for a base whose form
        was checked when it was verified (``verify.verify_joined``).
        """
        timing = self.timing
        problem = timing.structure_problem()
        if problem is not None:
            return f'its timing: {problem}'
        if not timing.slowest() >= -BACKWARDS:
            return f'its timing moves back (at {timing.slowest():.3g})'
        first, last = float(timing.states[0, 0]), float(timing.states[-1, 0])
        if not 0.0 <= first <= last <= self.base.duration:
            return (f'it runs over [{first:.9g}, {last:.9g}] s of a base of '
                    f'{self.base.duration:.9g} s')
        if not (last == self.base.duration or
                (timing.end_speed == 0.0 and timing.end_acceleration == 0.0)):
            return (f'it does not end at rest (speed {timing.end_speed:.3g}, acceleration '
                    f'{timing.end_acceleration:.3g})')
        return None

    def describe(self) -> dict:
        """Return the base and the timing as plain data."""
        return {'kind': self.kind, 'base': self.base.describe(),
                'timing': self.timing.describe()}

    @classmethod
    def described(cls, data: Mapping) -> 'Retimed':
        """Return the curve ``describe`` gave (raise ValueError if it is not one)."""
        base = data.get('base')
        if not isinstance(base, Mapping):
            raise ValueError('a retimed curve without a base curve')
        return cls(Trajectory.from_description(base),
                   JerkProfile.described(data.get('timing', {})))

    def backwards(self) -> 'Retimed':
        """Return the same motion backwards in time: the base backwards, sigma reflected."""
        t = self.timing
        states = t.states[::-1] * np.array([-1.0, 1.0, -1.0]) + \
            np.array([self.base.duration, 0.0, 0.0])
        return Retimed(self.base.backwards(), JerkProfile(
            t.duration - t.starts[::-1], t.jerks[::-1].copy(), states))
