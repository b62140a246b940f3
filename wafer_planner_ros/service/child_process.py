"""
A child process of the package, spoken to over a pair of pipes: work kept out of the node's.

A thread of the node waiting on a pipe leaves the interpreter lock to the rest of the
process, and a child at a lower scheduling priority leaves the cores to it: work done in a
child never holds up what the node answers at once (a stop request). ``ChildProcess(module,
name, wait)`` runs ``python -m module IN_FD OUT_FD``, started at its first use and again
after it ends (a crash there fails the one exchange under way, never the node). Every
message sent gets exactly one reply, in order; ``exchange`` sends one or more and returns
their replies, one caller at a time. What the child holds (moves, roadmaps) is named by the
caller's keys: ``held`` says which the running child holds, emptied when another starts.

The child's side: ``run_child`` reads the pipes from its arguments, lowers its own priority
and answers the messages one at a time (``serve``) until the pipe closes; ``load_kernels``
loads the compiled kernels as the node does.
"""

from multiprocessing.connection import Connection
import os
import pickle
import subprocess
import sys
import threading
import time
from typing import Callable, List, Optional, Sequence


class ChildProcess:
    """A child ``python -m module`` and the way to exchange messages with it (the module)."""

    def __init__(self, module: str, name: str, wait: float):
        """
        Start nothing yet: the child starts at the first exchange.

        ``name`` says which child in errors (``'the stop maker'``); ``wait``: seconds a reply
        is waited for at most, unless an exchange says otherwise.
        """
        self.module, self.name, self.wait = module, name, wait
        self._lock = threading.Lock()
        self._process: Optional[subprocess.Popen] = None
        self._pipes = None
        """(to the child, from the child) of the running child."""
        self.held = set()
        """Keys of what the running child holds (the callers' to fill; emptied at a start)."""
        self.started = 0
        """Children started so far."""

    def exchange(self, messages: Callable[[set], Sequence[tuple]],
                 wait: Optional[float] = None,
                 turn: Optional[float] = None) -> Optional[List[tuple]]:
        """
        Send ``messages(held)`` (started first if need be) and return their replies in order.

        ``messages`` is called once the child runs, with the keys it holds (it adds those
        its messages hand over). ``wait``: seconds for all the replies (default: the
        child's). ``turn``: seconds to wait for another caller's exchange to end (default:
        as long as it takes); None is returned, nothing sent, when it has not by then.
        Raises RuntimeError once the child fails, ends or does not reply in time (it is
        ended then: the next exchange starts another).
        """
        if not self._lock.acquire(timeout=-1 if turn is None else turn):
            return None
        try:
            return self._exchange(messages, self.wait if wait is None else wait)
        finally:
            self._lock.release()

    def _exchange(self, messages: Callable[[set], Sequence[tuple]], wait: float) -> List[tuple]:
        try:
            if self._process is None or self._process.poll() is not None:
                self._start()
            to_child, from_child = self._pipes
            sent = list(messages(self.held))
            for message in sent:
                to_child.send(message)
            replies, until = [], time.monotonic() + wait
            for _ in sent:
                if not from_child.poll(max(0.0, until - time.monotonic())):
                    raise RuntimeError(f'no reply in {wait:.0f} s')
                replies.append(from_child.recv())
            return replies
        except (OSError, EOFError, RuntimeError) as exc:
            process = self._process
            self._end()  # waits for it to end
            code = None if process is None else process.returncode
            why = 'its pipe closed' if isinstance(exc, EOFError) else str(exc) or repr(exc)
            raise RuntimeError(f'{self.name} ended (exit code {code}): {why}') from None

    def running(self) -> Optional[subprocess.Popen]:
        """Return the child's process while one is started (it may have ended since), else None."""
        return self._process

    def close(self, wait: float = 1.0, grace: float = 1.0) -> None:
        """
        End the child (it ends by itself once its pipe closes).

        Killed if a reply is still awaited after ``wait`` s (the waiting caller gets
        RuntimeError), or when it has not ended ``grace`` s after its pipe closed.
        """
        if self._lock.acquire(timeout=wait):
            try:
                self._end(grace)
            finally:
                self._lock.release()
            return
        process = self._process  # a reply is awaited: the waiting thread sees the child end
        if process is not None:
            process.kill()

    def _start(self) -> None:
        self._end()
        to_read, to_write = os.pipe()
        from_read, from_write = os.pipe()
        try:
            self._process = subprocess.Popen(
                [sys.executable, '-m', self.module, str(to_read), str(from_write)],
                pass_fds=(to_read, from_write), stdin=subprocess.DEVNULL, close_fds=True)
        finally:
            os.close(to_read)
            os.close(from_write)
        self._pipes = (Connection(to_write, readable=False), Connection(from_read,
                                                                        writable=False))
        self.held = set()
        self.started += 1

    def _end(self, grace: float = 1.0) -> None:
        if self._pipes is not None:
            for pipe in self._pipes:
                pipe.close()
            self._pipes = None
        if self._process is not None:
            try:
                self._process.wait(timeout=grace)
            except subprocess.TimeoutExpired:
                self._process.kill()
                self._process.wait()
            self._process = None


def run_child(argv: Optional[Sequence[str]], reply: Callable[[tuple], tuple], idle: bool,
              nice: int, prepare: Callable[[], None]) -> int:
    """
    Run a child: its priority lowered, ``prepare()``, then ``serve`` with ``reply``; return 0.

    ``argv``: its arguments, the pipes' descriptors (default ``sys.argv[1:]``). ``idle``:
    the idle scheduling class (it runs only on a core nothing else wants), else ``nice``
    steps lower than its parent; where neither is possible it runs as it is.
    """
    argv = sys.argv[1:] if argv is None else argv
    requests = Connection(int(argv[0]), writable=False)
    replies = Connection(int(argv[1]), readable=False)
    try:
        if not idle:
            raise OSError('nice')
        os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
    except (AttributeError, OSError):
        try:
            os.nice(nice)
        except OSError:
            pass
    prepare()
    serve(requests, replies, reply)
    return 0


def serve(requests: Connection, replies: Connection, reply: Callable[[tuple], tuple]) -> None:
    """Send ``reply(message)`` for every message on ``requests`` until it closes."""
    while True:
        try:
            message = requests.recv()
        except (EOFError, OSError):
            return
        try:
            answer = reply(message)
        except Exception as exc:  # noqa: B902 - told to the parent, which goes on
            answer = ('error', f'{type(exc).__name__}: {exc}')
        try:
            try:
                replies.send(answer)
            except (pickle.PicklingError, TypeError, AttributeError) as exc:
                replies.send(('error', f'its answer could not be sent: {type(exc).__name__}: '
                                       f'{exc}'))
        except (BrokenPipeError, OSError):
            return


def load_kernels() -> None:
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
