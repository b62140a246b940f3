"""
What a timed joint-space curve offers to everything after the planner.

In the spirit of toppra's ``AbstractGeometricPath`` and drake's ``Trajectory``: verification,
reports, markers, recordings and figures use only this interface, never a particular kind
of curve, so that a new way of shaping or timing one plugs in without touching them. A curve
stored as plain data (``describe``, e.g. in the station table) comes back through
``Trajectory.from_description``, which makes the kind of curve it names: each kind registers
itself by its ``kind`` name when its class is defined.
"""

from abc import ABC, abstractmethod
from typing import ClassVar, Dict, Mapping, Optional, Sequence, Tuple

import numpy as np


BREAK_GAP = 1e-3
"""s: the least time between a break and a time of the sampling grid kept beside it."""
SAME_TIME = 1e-9
"""s: sample times nearer than this are one."""
UNNAMED_KIND = 'cubic-b-spline'
"""The kind of a description that names none (written before kinds were named)."""


class Trajectory(ABC):
    """
    A curve q(t) in joint space for t in [0, duration], ending at rest.

    Every kind starts at rest too, but for a curve that continues a motion (a controlled
    stop, ``retimed.Retimed``): it starts in the state of the curve it continues.
    """

    kind: ClassVar[str] = ''
    """The name its descriptions give (``describe``); empty for an abstract kind."""
    _kinds: ClassVar[Dict[str, type]] = {}

    def __init_subclass__(cls, **options):
        """Register a kind of curve by its ``kind`` name."""
        super().__init_subclass__(**options)
        if cls.kind:
            Trajectory._kinds[cls.kind] = cls

    @staticmethod
    def from_description(data: Mapping) -> 'Trajectory':
        """
        Return the curve a ``describe`` gave, of the kind it names.

        Raise ValueError when the kind is unknown or the data does not make such a curve;
        whether the curve is a usable motion is ``ill_formed``'s to say.
        """
        kind = data.get('kind', UNNAMED_KIND)
        made = Trajectory._kinds.get(kind) if isinstance(kind, str) else None
        if made is None:
            raise ValueError(f'unknown kind of curve {str(kind)[:80]!r} (known: '
                             f'{", ".join(sorted(Trajectory._kinds))})')
        return made.described(data)

    @classmethod
    @abstractmethod
    def described(cls, data: Mapping) -> 'Trajectory':
        """Return the curve of this kind that ``describe`` gave (raise ValueError if not)."""

    @property
    @abstractmethod
    def duration(self) -> float:
        """Return the total time T (s)."""

    @abstractmethod
    def evaluate_orders(self, t, orders: Sequence[int] = (0, 1, 2)) -> Tuple[np.ndarray, ...]:
        """Return the derivatives of the given orders at times t (clipped to [0, T])."""

    def evaluate(self, t, order: int = 0) -> np.ndarray:
        """Return q (order 0), q', q'' or q''' at times t (clipped to [0, T]), (len(t), J)."""
        return self.evaluate_orders(t, (order,))[0]

    @abstractmethod
    def ill_formed(self, start: np.ndarray, goal: np.ndarray) -> Optional[str]:
        """
        Return what makes the curve no motion at rest from ``start`` to ``goal``, or None.

        Checked before anything is evaluated on it: the data defining the curve (finite,
        consistent, spanning [0, T]) and its ends, exactly at ``start`` and ``goal`` with
        zero velocity there.
        """

    def ends_problem(self, start: np.ndarray, goal: np.ndarray) -> Optional[str]:
        """Return how the curve misses ``start`` at 0 or ``goal`` at T exactly, or None."""
        q0, q1 = self.evaluate([0.0, self.duration], 0)
        if not np.array_equal(q0, np.asarray(start, float)):
            return f'it starts at {q0.tolist()}, not at the start {np.asarray(start).tolist()}'
        if not np.array_equal(q1, np.asarray(goal, float)):
            return f'it ends at {q1.tolist()}, not at the goal {np.asarray(goal).tolist()}'
        return None

    @abstractmethod
    def breaks(self) -> np.ndarray:
        """Return the times (S + 1,) between the curve's polynomial pieces, 0 to T."""

    def covering_breaks(self) -> np.ndarray:
        """
        Return ``breaks`` cut to [0, T] with 0 and T added: pieces covering all of [0, T].

        Evaluated before its first break or after its last, a curve continues its first or
        last polynomial piece, so each added piece lies within one polynomial too. For a
        well-formed curve (``ill_formed``) these are the breaks themselves; for another they
        make whatever is evaluated at [0, T] checked all the same.
        """
        breaks, duration = self.breaks(), self.duration
        inside = breaks[(breaks > 0.0) & (breaks < duration)]
        return np.concatenate([[0.0], inside, [duration]])

    @abstractmethod
    def peak_speed(self, a, b) -> np.ndarray:
        """
        Return the exact largest |q'_j| of every joint on each interval [a_k, b_k], (K, J).

        Each interval lies within one polynomial piece (between two ``breaks``).
        """

    def pieces(self, subdivisions: int = 8) -> Tuple[np.ndarray, np.ndarray]:
        """
        Return (boundaries (S + 1,), peaks (S, J)): the curve in pieces and each one's peaks.

        Every polynomial piece (``covering_breaks``: all of [0, T]) is cut into
        ``subdivisions`` equal pieces; ``peaks`` are the exact largest |q'_j| of every joint
        on each.
        """
        breaks = self.covering_breaks()
        steps = np.arange(subdivisions) / subdivisions
        boundaries = (breaks[:-1, None] + np.diff(breaks)[:, None] * steps).ravel()
        boundaries = np.append(boundaries, breaks[-1])
        return boundaries, self.peak_speed(boundaries[:-1], boundaries[1:])

    def samples(self, period: float) -> Tuple[np.ndarray, ...]:
        """
        Return (times, q, q', q''): every ``period`` s from 0, at each break, the exact end.

        At the curve's breaks too (``covering_breaks``: where its jerk jumps), so that a
        controller that joins the samples by quintics (``joint_trajectory_controller``)
        follows each of the curve's pieces of degree five or less exactly, never a quintic
        across a jump of the jerk (with samples every 10 ms alone that left the curve by
        up to 2e-7 rad, the wafer limit by up to 1.1 % and the jerk limit by up to 58 % on
        the default cell's moves). A time of the grid nearer a break than ``BREAK_GAP``
        gives way to it; breaks nearer each other than ``SAME_TIME`` count as one.
        """
        duration = self.duration
        grid = np.arange(0.0, duration - 1e-9, period)
        breaks = self.covering_breaks()[1:-1]
        if len(breaks):
            after = np.clip(np.searchsorted(breaks, grid), 0, len(breaks) - 1)
            before = np.clip(after - 1, 0, len(breaks) - 1)
            nearest = np.minimum(np.abs(grid - breaks[after]), np.abs(grid - breaks[before]))
            grid = grid[(nearest >= min(BREAK_GAP, 0.5 * period)) | (grid == 0.0)]
        times = np.unique(np.concatenate([grid, breaks, [duration]]))
        times = times[np.concatenate([[True], np.diff(times) > SAME_TIME])]
        times[-1] = duration
        return (times, *self.evaluate_orders(times))

    @abstractmethod
    def describe(self) -> Mapping:
        """Return the curve as plain data (lists and numbers, and its ``kind``) exactly."""

    @abstractmethod
    def backwards(self) -> 'Trajectory':
        """Return the same motion backwards in time: q(T - t)."""
