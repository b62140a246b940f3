"""
Stops found in a process of their own, so that finding them never holds up an answer.

Stops are made ahead of a running move (``prepared_stops``) so that a stop request is
answered at once; finding one (``stopping.controlled_stop``) is some milliseconds of
Python and numpy per moment. In the node's own process that work holds the interpreter
lock against the thread answering the requests, however little of a core it takes:
measured in one process with a planning thread beside it, the answer took 2.1 ms at the
median and 4.2 ms at p99 while no stop was being found, 3.4 and 10.2 ms while one was.

``StopMaker`` finds them in a child process (``python -m
wafer_planner_ros.service.stop_maker``, a ``child_process.ChildProcess`` at the idle
scheduling priority: nothing waits for it), started at its first use and again after it
ends. ``finder(trajectory, robot)`` hands the child a move once and returns the function
that asks it for the stop from a moment: the caller waits on the pipe, leaving the lock to
the rest of the process, and gets the stop's timing back, which it puts on its own move (the
``Stop`` of that very curve, as ``planner.stop`` requires). What the child sends is a
draft only: the caller verifies it (``planner.stop.prepare``) as any stop is.
"""

import itertools
import sys
from typing import Callable

from wafer_planner_ros.errors import ErrorCode, PlanningError
from wafer_planner_ros.service.child_process import ChildProcess, load_kernels, run_child
from wafer_planner_ros.trajectory.jerk_profile import JerkProfile
from wafer_planner_ros.trajectory.retimed import Retimed
from wafer_planner_ros.trajectory.stopping import controlled_stop, Stop

MOVES = 4
"""Moves the child holds (the oldest forgotten first): the running one, and a few before."""
REPLY_WAIT = 120.0
"""s a stop is waited for at most (the child's first may load or compile its kernels)."""
NICE = 10
"""How much lower the child's scheduling priority is than its parent's, where the idle
scheduling class is refused."""


class StopMaker:
    """The child process finding stops, and the way to ask it (the module's description)."""

    def __init__(self):
        """Start nothing yet: the child starts at the first stop asked for."""
        self._child = ChildProcess('wafer_planner_ros.service.stop_maker', 'the stop maker',
                                   REPLY_WAIT)
        self._keys = itertools.count()

    @property
    def started(self) -> int:
        """Return how many children were started so far."""
        return self._child.started

    def finder(self, trajectory, robot) -> Callable[[float], Stop]:
        """
        Return ``find(moment)``: the controlled stop of ``trajectory`` from ``moment``.

        Found by the child under ``robot``'s limit set, as ``controlled_stop`` finds it,
        then made a stop of ``trajectory`` itself. ``find`` raises PlanningError as
        ``controlled_stop`` does, RuntimeError when the child failed or ended (the next
        call starts another).
        """
        key = next(self._keys)

        def find(moment: float) -> Stop:
            def messages(held: set) -> list:
                sent = [] if key in held else [('move', key, trajectory, robot)]
                held.add(key)
                return sent + [('make', key, float(moment))]

            reply = self._child.exchange(messages)[-1]
            if reply[0] == 'planning':
                raise PlanningError(ErrorCode[reply[1]], reply[2])
            if reply[0] != 'made':
                raise RuntimeError(f'the stop maker failed: {reply[1]}')
            starts, jerks, states, breaks, share, timing = reply[1:]
            return Stop(Retimed(trajectory, JerkProfile(starts, jerks, states), breaks), share,
                        timing)
        return find

    def close(self) -> None:
        """End the child (it ends by itself once its pipe closes); killed if one is awaited."""
        self._child.close()


class _Maker:
    """The child's side: the moves it holds, and the stops it finds on them."""

    def __init__(self):
        self.moves = {}

    def reply(self, message: tuple) -> tuple:
        """Hold a move (``('move', key, trajectory, robot)``) or find a stop on one."""
        if message[0] == 'move':
            _, key, trajectory, robot = message
            self.moves[key] = (trajectory, robot)
            for old in sorted(self.moves)[:-MOVES]:
                del self.moves[old]
            return ('held', key)
        _, key, moment = message
        trajectory, robot = self.moves[key]
        try:
            stop = controlled_stop(trajectory, moment, robot)
        except PlanningError as exc:
            return ('planning', exc.code.name, exc.message)
        curve = stop.trajectory
        return ('made', curve.timing.starts, curve.timing.jerks, curve.timing.states,
                curve.breaks(), stop.share, stop.timing)


def main(argv=None) -> int:
    """Run the child: ``python -m wafer_planner_ros.service.stop_maker IN_FD OUT_FD``."""
    return run_child(argv, _Maker().reply, idle=True, nice=NICE, prepare=load_kernels)


if __name__ == '__main__':
    sys.exit(main())
