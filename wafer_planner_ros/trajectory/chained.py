"""
Curves played one after the other as one motion: a controlled stop, then a move from rest.

A move diverted while it moves, where no one curve from its moving state is found
(``continuing``), is its controlled stop (``retimed.Retimed``) and the move from where
that stop rests to the new goal, as one trajectory. ``Chained`` plays
its parts in turn: each part starts exactly where the one before it ends, in position, and
at rest in velocity and acceleration (where a stop ends and a move from rest begins), so
the motion is continuous in acceleration by construction; its pieces are the parts'.
"""

from typing import ClassVar, Mapping, Optional, Sequence

import numpy as np

from wafer_planner_ros.trajectory.curve import Trajectory

JOIN_TOLERANCE = 1e-9
"""rad/s, rad/s^2: how far from rest two parts may meet (rounding)."""


class Chained(Trajectory):
    """Curves played one after the other (the module)."""

    kind: ClassVar[str] = 'chained'

    def __init__(self, parts: Sequence[Trajectory]):
        """Keep the parts, in the order they are played."""
        if not parts:
            raise ValueError('a chain of no curves')
        self.parts = tuple(parts)
        self._starts = np.concatenate([[0.0], np.cumsum([p.duration for p in self.parts])])

    @property
    def duration(self) -> float:
        """Return the total time (s)."""
        return float(self._starts[-1])

    def _part_of(self, t: np.ndarray, strict: bool = False) -> np.ndarray:
        """Return the part each time falls in (a join: the part before it, unless strict)."""
        side = 'right' if strict else 'left'
        return np.clip(np.searchsorted(self._starts, t, side=side) - 1, 0, len(self.parts) - 1)

    def evaluate_orders(self, t, orders=(0, 1, 2)) -> tuple:
        """Return the derivatives of the given orders at times t, each (len(t), J)."""
        t = np.clip(np.atleast_1d(np.asarray(t, float)), 0.0, self.duration)
        part = self._part_of(t)
        out = None
        for k, curve in enumerate(self.parts):
            here = part == k
            if not here.any():
                continue
            # The chain's end is the last part's, exactly (the sum of the parts' durations
            # less the last part's start can fall short of it by a rounding).
            local = np.where(t[here] >= self.duration, curve.duration,
                             t[here] - self._starts[k])
            values = curve.evaluate_orders(local, orders)
            if out is None:
                out = [np.empty((len(t), v.shape[1])) for v in values]
            for target, value in zip(out, values):
                target[here] = value
        return tuple(out)

    def breaks(self) -> np.ndarray:
        """Return every part's breaks, in the chain's time."""
        return np.unique(np.concatenate([curve.breaks() + start for curve, start
                                         in zip(self.parts, self._starts)]))

    def peak_speed(self, a, b) -> np.ndarray:
        """Return each part's bound of every |q'_j| on [a_k, b_k] (within one of its pieces)."""
        a, b = np.atleast_1d(np.asarray(a, float)), np.atleast_1d(np.asarray(b, float))
        part = self._part_of(0.5 * (a + b), strict=True)
        peaks = None
        for k, curve in enumerate(self.parts):
            here = part == k
            if not here.any():
                continue
            values = curve.peak_speed(a[here] - self._starts[k], b[here] - self._starts[k])
            if peaks is None:
                peaks = np.empty((len(a), values.shape[1]))
            peaks[here] = values
        return peaks

    def ill_formed(self, start: np.ndarray, goal: np.ndarray) -> Optional[str]:
        """
        Return what makes the parts no motion from ``start`` to rest at ``goal``, or None.

        Each part well formed between its own ends, the first from ``start``, the last to
        ``goal``; where two meet, the same configuration exactly and both at rest there.
        """
        ends = [curve.evaluate([0.0, curve.duration], 0) for curve in self.parts]
        for k, (curve, (first, last)) in enumerate(zip(self.parts, ends)):
            problem = curve.ill_formed(start if k == 0 else first,
                                       goal if k == len(self.parts) - 1 else last)
            if problem is not None:
                return f'part {k}: {problem}'
        for k in range(1, len(self.parts)):
            if not np.array_equal(ends[k - 1][1], ends[k][0]):
                return f'part {k} does not start where part {k - 1} ends'
            before = self.parts[k - 1].evaluate_orders([self.parts[k - 1].duration], (1, 2))
            after = self.parts[k].evaluate_orders([0.0], (1, 2))
            gap = float(np.abs(np.concatenate([*before, *after])).max())
            if not gap <= JOIN_TOLERANCE:
                return f'parts {k - 1} and {k} do not meet at rest (by {gap:.3g})'
        return None

    def describe(self) -> dict:
        """Return the parts as plain data."""
        return {'kind': self.kind, 'parts': [curve.describe() for curve in self.parts]}

    @classmethod
    def described(cls, data: Mapping) -> 'Chained':
        """Return the chain ``describe`` gave (raise ValueError if it is not one)."""
        parts = data.get('parts')
        if not isinstance(parts, list) or not parts:
            raise ValueError('a chain of curves without its parts')
        return cls([Trajectory.from_description(part) for part in parts])

    def backwards(self) -> 'Chained':
        """Return the same motion backwards in time: the parts backwards, in reverse."""
        return Chained([curve.backwards() for curve in reversed(self.parts)])
