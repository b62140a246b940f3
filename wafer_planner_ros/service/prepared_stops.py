"""
Controlled stops made before they are asked for: a moving robot's stops, a few ms apart.

A stop request wants its answer at once (the robot moves on meanwhile), and finding a
controlled stop (``trajectory.stopping``) takes from a few to some tens of milliseconds.
So while a published move runs, its stops are made ahead: ``PreparedStops`` holds the
stops of one move from moments ``EVERY`` s apart (0, EVERY, 2 EVERY, ...), made in the
order the move reaches them, from where it is (``wanted``), ``AHEAD`` s ahead at most.
A request to stop at ``at`` then takes the stop of the first moment made at or after
``at`` within a stride (``ahead_of``): the answer follows the move from ``at`` to that
moment and brakes from there as that stop does (``Planner.stop``'s ``ahead``; the rest of
the move where that is sooner). Each stop is verified as it is made
(``planner.stop.prepare``), so a request checks only the stretch of the move it follows
and the join (``verify.verify_joined``). A moment not yet made is found for ``at``
itself, as without this.

Making them costs a core's time in proportion to how long a stop takes to make (its mean
so far) over the time between two moments made: where stops take long (a move through
the ports, ~20 ms each), only every ``stride``-th moment is made, so that keeping pace
with the move takes about a share of a core (``SHARE`` by default, the node's
``stops.ahead_share``; the moments up to ``AHEAD`` ahead of a move's start are made at
once, as fast as a core allows); a request is then followed at most a stride of moments
before it brakes.

The stops are made with the move's own limit set and kept only while they are ahead of
the move (``forget_before``); nothing here is published: each is a part of an answer,
whose whole is checked as it is made one.
"""

import math
import threading
import time
from typing import Callable, Dict, Optional

from wafer_planner_ros.errors import PlanningError
from wafer_planner_ros.planner.stop import Prepared

EVERY = 0.02
"""s of a move between the moments whose stops may be made ahead."""
AHEAD = 0.5
"""s of a move ahead of where it is whose stops are made."""
SHARE = 0.5
"""The share of a core that making stops ahead keeps to by default (``stride``)."""


class PreparedStops:
    """The stops of one move made ahead (the module's description); safe across threads."""

    def __init__(self, trajectory, make: Callable[[float], Optional[Prepared]]):
        """
        Make the stops of ``trajectory`` (a published move) with ``make(moment)``.

        ``make``: the stop from ``moment`` s of the move, verified (``planner.stop.prepare``
        under the move's limit set, with its verification), None where none is made.
        """
        self.trajectory, self._make = trajectory, make
        self._lock = threading.Lock()
        self._made: Dict[int, Optional[Prepared]] = {}
        """moment index -> its stop (None: none there, e.g. the move rests)."""
        self._making = [0, 0.0]
        """Stops made, the seconds that took."""
        self._given_up = False

    def give_up(self) -> None:
        """Make no more stops of this move (one failed to be made: ``wanted`` says none)."""
        self._given_up = True

    def stride(self, share: float = SHARE) -> int:
        """
        Return every how many moments one is made to keep to ``share`` of a core (> 0).

        1 until one has been made; then the mean time one took over ``share`` of ``EVERY``.
        """
        with self._lock:
            made, seconds = self._making
        if not made:
            return 1
        return max(1, int(math.ceil(seconds / made / (share * EVERY))))

    @property
    def count(self) -> int:
        """Return how many moments' stops are held."""
        with self._lock:
            return len(self._made)

    def wanted(self, elapsed: float, share: float = SHARE) -> Optional[int]:
        """
        Return the next moment (index) to make for a move ``elapsed`` s along; None: none.

        The first moment after ``elapsed`` on the ``stride`` for ``share`` not yet made, no
        further than ``AHEAD`` ahead and strictly inside the move.
        """
        if self._given_up:
            return None
        stride = self.stride(share)
        first = max(int(math.floor(max(elapsed, 0.0) / EVERY)) + 1, 1)
        first += -first % stride
        last = min(int(math.floor((elapsed + AHEAD) / EVERY)),
                   int(math.ceil(self.trajectory.duration / EVERY)) - 1)
        with self._lock:
            for index in range(first, last + 1, stride):
                if index not in self._made:
                    return index
        return None

    def make(self, index: int) -> None:
        """Make the stop from moment ``index`` (``make``) and hold it."""
        begun = time.perf_counter()
        try:
            stop = self._make(index * EVERY)
        except PlanningError:
            stop = None  # at rest there: a request there is refused as it would be anyway
        with self._lock:
            self._made[index] = stop
            self._making[0] += 1
            self._making[1] += time.perf_counter() - begun

    def ahead_of(self, at: float, share: float = SHARE) -> Optional[Prepared]:
        """
        Return the stop made from the first moment at or after ``at``; None: not made.

        Within a stride of moments (``stride`` for ``share``): a request is followed no
        further.
        """
        index = int(math.ceil(at / EVERY))
        if index > 0 and (index - 1) * EVERY >= at:  # rounding, either way
            index -= 1
        elif index * EVERY < at:
            index += 1
        stride = self.stride(share)
        with self._lock:
            for moment in range(index, index + stride):
                if moment in self._made:
                    return self._made[moment]
        return None

    def forget_before(self, elapsed: float) -> None:
        """Drop the stops of the moments the move has passed (``elapsed`` s along)."""
        with self._lock:
            for index in [k for k in self._made if k * EVERY < elapsed]:
                del self._made[index]
