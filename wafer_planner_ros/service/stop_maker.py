"""
Stops found in a process of their own, so that finding them never holds up an answer.

Stops are made ahead of a running move (``prepared_stops``) so that a stop request is
answered at once; finding one (``stopping.controlled_stop``) is some milliseconds of
Python and numpy per moment. In the node's own process that work holds the interpreter
lock against the thread answering the requests, however little of a core it takes:
measured in one process with a planning thread beside it, the answer took 2.1 ms at the
median and 4.2 ms at p99 while no stop was being found, 3.4 and 10.2 ms while one was.

``StopMaker`` finds them in a child process (``python -m
wafer_planner_ros.service.stop_maker``, run at a lower scheduling priority: nothing waits
for it), started at its first use and again after it ends, over a pair of pipes.
``finder(trajectory, robot)`` hands the child a move once and returns the function that
asks it for the stop from a moment: the caller waits on the pipe, leaving the lock to the
rest of the process, and gets the stop's timing back, which it puts on its own move (the
``Stop`` of that very curve, as ``planner.stop`` requires). What the child sends is a
draft only: the caller verifies it (``planner.stop.prepare``) as any stop is.
"""

import itertools
from multiprocessing.connection import Connection
import os
import subprocess
import sys
import threading
from typing import Callable, Optional

from wafer_planner_ros.errors import ErrorCode, PlanningError
from wafer_planner_ros.trajectory.jerk_profile import JerkProfile
from wafer_planner_ros.trajectory.retimed import Retimed
from wafer_planner_ros.trajectory.stopping import controlled_stop, Stop

MOVES = 4
"""Moves the child holds (the oldest forgotten first): the running one, and a few before."""
REPLY_WAIT = 120.0
"""s a stop is waited for at most (the child's first may load or compile its kernels)."""
NICE = 10
"""How much lower the child's scheduling priority is than its parent's."""


class StopMaker:
    """The child process finding stops, and the way to ask it (the module's description)."""

    def __init__(self):
        """Start nothing yet: the child starts at the first stop asked for."""
        self._lock = threading.Lock()
        self._process: Optional[subprocess.Popen] = None
        self._pipes = None
        """(to the child, from the child) of the running child."""
        self._sent = set()
        """Keys of the moves the running child holds."""
        self._keys = itertools.count()
        self.started = 0
        """Children started so far."""

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
            reply = self._ask(key, trajectory, robot, float(moment))
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
        if self._lock.acquire(timeout=1.0):
            try:
                self._end()
            finally:
                self._lock.release()
            return
        process = self._process  # a stop is awaited: the waiting thread sees the child end
        if process is not None:
            process.kill()

    def _ask(self, key: int, trajectory, robot, moment: float) -> tuple:
        with self._lock:
            try:
                if self._process is None or self._process.poll() is not None:
                    self._start()
                to_child, from_child = self._pipes
                if key not in self._sent:
                    to_child.send(('move', key, trajectory, robot))
                    self._sent.add(key)
                to_child.send(('make', key, moment))
                if not from_child.poll(REPLY_WAIT):
                    raise RuntimeError(f'no stop from the stop maker in {REPLY_WAIT:.0f} s')
                return from_child.recv()
            except (OSError, EOFError, RuntimeError) as exc:
                code = None if self._process is None else self._process.poll()
                self._end()
                raise RuntimeError(f'the stop maker ended (exit code {code}): {exc}') from None

    def _start(self) -> None:
        self._end()
        to_read, to_write = os.pipe()
        from_read, from_write = os.pipe()
        try:
            self._process = subprocess.Popen(
                [sys.executable, '-m', 'wafer_planner_ros.service.stop_maker', str(to_read),
                 str(from_write)], pass_fds=(to_read, from_write), stdin=subprocess.DEVNULL,
                close_fds=True)
        finally:
            os.close(to_read)
            os.close(from_write)
        self._pipes = (Connection(to_write, readable=False), Connection(from_read,
                                                                        writable=False))
        self._sent = set()
        self.started += 1

    def _end(self) -> None:
        if self._pipes is not None:
            for pipe in self._pipes:
                pipe.close()
            self._pipes = None
        if self._process is not None:
            try:
                self._process.wait(timeout=1.0)
            except subprocess.TimeoutExpired:
                self._process.kill()
                self._process.wait()
            self._process = None


def serve(requests: Connection, replies: Connection) -> None:
    """Find the stops asked for on ``requests`` until it closes (the child's loop)."""
    moves = {}
    while True:
        try:
            message = requests.recv()
        except (EOFError, OSError):
            return
        if message[0] == 'move':
            _, key, trajectory, robot = message
            moves[key] = (trajectory, robot)
            for old in sorted(moves)[:-MOVES]:
                del moves[old]
            continue
        _, key, moment = message
        try:
            trajectory, robot = moves[key]
            stop = controlled_stop(trajectory, moment, robot)
            curve = stop.trajectory
            reply = ('made', curve.timing.starts, curve.timing.jerks, curve.timing.states,
                     curve.breaks(), stop.share, stop.timing)
        except PlanningError as exc:
            reply = ('planning', exc.code.name, exc.message)
        except Exception as exc:  # noqa: B902 - told to the parent, which goes on
            reply = ('error', f'{type(exc).__name__}: {exc}')
        try:
            replies.send(reply)
        except (BrokenPipeError, OSError):
            return


def _load_kernels() -> None:
    """Load the compiled kernels as the node does (built ahead, else numba's cache)."""
    from wafer_planner_ros import kernels, kernels_lookup
    from wafer_planner_ros.service import warmup  # noqa: F401 - every kernel's module
    try:
        if kernels_lookup.load_ahead():
            return
    except Exception:  # noqa: B902 - no build ahead here: numba's cache, or compiled
        pass
    try:
        kernels.load_cached()
    except Exception:  # noqa: B902 - then they compile when first used
        pass


def main(argv=None) -> int:
    """Run the child: ``python -m wafer_planner_ros.service.stop_maker IN_FD OUT_FD``."""
    argv = sys.argv[1:] if argv is None else argv
    requests = Connection(int(argv[0]), writable=False)
    replies = Connection(int(argv[1]), readable=False)
    try:
        os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
    except (AttributeError, OSError):
        try:
            os.nice(NICE)
        except OSError:
            pass
    _load_kernels()
    serve(requests, replies)
    return 0


if __name__ == '__main__':
    sys.exit(main())
