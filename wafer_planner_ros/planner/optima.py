"""
A planner's library of optima: the curves it answered, drafts for the requests near them.

Every verified answer between two configurations at rest that the whole-curve optimisation
made (``candidates``), and every station table entry handed to it (``service``), is kept
by its ends, the last ``OPTIMA_KEPT`` of them, the fastest for the same ends. A request
planned within a time budget whose two ends lie within ``REACH`` of a kept optimum's (on
every joint; the optimum run backwards counts too: the same limits hold on it) starts its
optimisation from that curve, moved to its ends (``trajectory.warm``), instead of from
the corridor: near the optimum, it is proven in a round or two. A kept curve is never
trusted: it is a draft, moved to the request's ends, proven there (else not a start to
return) and optimised; the answer, that draft only where nothing found beats it, is
verified for the request like any. Safe to share between threads.
"""

from dataclasses import dataclass
import threading
from typing import List, Optional

import numpy as np

from wafer_planner_ros.trajectory.bspline import CubicBSpline

OPTIMA_KEPT = 256
"""The most optima a planner keeps (the oldest out first): a few hundred kilobytes."""
REACH = 0.5
"""rad: how far (on any joint, at either end) a request's ends may lie from a kept
optimum's for it to be the request's draft. Measured when it was chosen, on the default
cell (roadmap seed 1), the unbudgeted answers of 8 random joint pairs with both ends then
moved at random by up to 0.05, 0.2 and 0.5 rad on each joint (up to 24 requests each),
the whole-curve optimisation alone within the 0.12 s budget: from the moved answer
within 0.2 % of the unbudgeted optimum at the median and 1.008, 1.017 and 1.054 × at
worst, in 21, 43 and 77 ms (median); from the corridor 1.002–1.056 × at the median, 1.32,
1.75 and 1.50 × at worst, in 82, 75 and 132 ms."""


@dataclass(frozen=True, eq=False)
class Optimum:
    """A verified curve between two configurations, at rest at both."""

    start: np.ndarray
    goal: np.ndarray
    curve: CubicBSpline
    serial: int = 0
    """Its place in the order kept (``Optima.since``)."""


class Optima:
    """The optima a planner keeps (the module), bounded, by their ends."""

    def __init__(self, size: int = OPTIMA_KEPT, reach: float = REACH):
        """Keep at most ``size``; a draft lies within ``reach`` rad of a request's ends."""
        self._size, self._reach = size, reach
        self._kept = {}
        self._ends = None
        """(count, 6): the kept optima's start and goal, made when first searched."""
        self._serial = 0
        self._lock = threading.Lock()

    @property
    def serial(self) -> int:
        """Return the serial of the last optimum kept (0: none yet)."""
        with self._lock:
            return self._serial

    def __len__(self) -> int:
        """Return how many optima are kept."""
        with self._lock:
            return len(self._kept)

    def add(self, start, goal, curve: CubicBSpline) -> bool:
        """
        Keep ``curve`` from ``start`` to ``goal``; return whether it was kept.

        Not kept when as fast a curve is kept for the same ends; the oldest goes beyond
        the bound.
        """
        start, goal = (np.array(q, float) for q in (start, goal))
        key = start.tobytes() + goal.tobytes()
        with self._lock:
            kept = self._kept.get(key)
            if kept is not None and kept.curve.duration <= curve.duration:
                return False
            self._kept.pop(key, None)
            if len(self._kept) >= self._size:
                del self._kept[next(iter(self._kept))]
            self._serial += 1
            self._kept[key] = Optimum(start, goal, curve, self._serial)
            self._ends = None
            return True

    def since(self, serial: int) -> List[Optimum]:
        """Return the optima kept after ``serial`` (``Optimum.serial``) and still kept."""
        with self._lock:
            return [optimum for optimum in self._kept.values() if optimum.serial > serial]

    def entries(self) -> List[Optimum]:
        """Return the kept optima, the oldest first."""
        with self._lock:
            return list(self._kept.values())

    def nearest(self, start, goal) -> Optional[CubicBSpline]:
        """
        Return the kept curve whose ends are nearest ``start`` and ``goal``, or None.

        Nearest by the largest joint offset at either end, within ``REACH``; run backwards
        when its goal is near ``start``. The curve is as kept: ``trajectory.warm.moved_to``
        takes it to the request's ends.
        """
        with self._lock:
            if not self._kept:
                return None
            if self._ends is None:
                self._ends = np.array([np.concatenate([o.start, o.goal])
                                       for o in self._kept.values()])
            ends, optima = self._ends, list(self._kept.values())
        start, goal = np.asarray(start, float), np.asarray(goal, float)
        ahead = np.abs(ends - np.concatenate([start, goal])).max(axis=1)
        back = np.abs(ends - np.concatenate([goal, start])).max(axis=1)
        k, j = int(np.argmin(ahead)), int(np.argmin(back))
        if min(ahead[k], back[j]) > self._reach:
            return None
        return optima[k].curve if ahead[k] <= back[j] else optima[j].curve.backwards()
