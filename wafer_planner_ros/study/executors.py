"""
Where a study's variants run: worker processes on this machine, or a Ray cluster.

Both take tasks (a key and a payload for ``evaluate.task``) one at a time and hand back
outcomes as they finish: the row, or why the attempt failed (the function raised, or the
worker died, in which case a new worker takes its place). Retrying is the caller's
(``runner``), the same for both.
"""

import multiprocessing
from multiprocessing.connection import wait
import os
import signal
import socket
from typing import Callable, Dict, Optional, Tuple

from wafer_planner_ros.study.evaluate import task as evaluate_task

Outcome = Tuple[str, Optional[dict], str]
"""(key, row or None, why the attempt failed)."""


def _serve(connection, function) -> None:
    """Run ``function`` on each payload received; send back the row or the error."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the study's: it stops us
    while True:
        try:
            payload = connection.recv()
        except (EOFError, OSError, KeyboardInterrupt):
            return  # the study has gone
        try:
            reply = ('row', function(payload))
        except Exception as exc:  # noqa: B902 - sent back: the caller retries or records it
            reply = ('error', f'{type(exc).__name__}: {exc}')
        try:
            connection.send(reply)
        except (OSError, KeyboardInterrupt):
            return


class LocalExecutor:
    """Worker processes on this machine (started fresh: ``spawn``), one task each."""

    def __init__(self, workers: Optional[int] = None, function: Callable = evaluate_task):
        """Start ``workers`` processes (default: one per core this process may use)."""
        self.workers = workers or len(os.sched_getaffinity(0))
        self.where = f'{self.workers} local worker processes'
        self._function = function
        self._context = multiprocessing.get_context('spawn')
        self._idle = [self._start() for _ in range(self.workers)]
        self._busy: Dict[object, Tuple[object, str]] = {}
        """connection -> (process, key)."""

    def _start(self):
        ours, theirs = self._context.Pipe()
        process = self._context.Process(target=_serve, args=(theirs, self._function),
                                        name='wafer-study-worker', daemon=True)
        process.start()
        theirs.close()
        return process, ours

    @property
    def free(self) -> int:
        """Return how many more tasks can start now."""
        return len(self._idle)

    def submit(self, key: str, payload: dict) -> None:
        """Start ``payload`` on an idle worker."""
        process, connection = self._idle.pop()
        try:
            connection.send(payload)
        except OSError:  # it died idle: a new one takes the task
            connection.close()
            process, connection = self._start()
            connection.send(payload)
        self._busy[connection] = (process, key)

    def next_done(self) -> Outcome:
        """Wait for a task to end; return its outcome."""
        by_sentinel = {process.sentinel: connection
                       for connection, (process, _) in self._busy.items()}
        ready = wait(list(self._busy) + list(by_sentinel))
        connection = next((r for r in ready if r in self._busy), None)
        if connection is None:
            connection = by_sentinel[ready[0]]
        process, key = self._busy.pop(connection)
        try:
            kind, value = connection.recv()
        except (EOFError, OSError):
            process.join(5)
            connection.close()
            self._idle.append(self._start())
            return key, None, f'the worker died (exit code {process.exitcode})'
        self._idle.append((process, connection))
        return (key, value, '') if kind == 'row' else (key, None, value)

    def close(self) -> None:
        """Stop the workers (a task under way is abandoned)."""
        for process, connection in self._idle + [(p, c) for c, (p, _) in self._busy.items()]:
            connection.close()
            process.join(1)
            if process.is_alive():
                process.kill()
                process.join()
        self._idle, self._busy = [], {}


def _check_reachable(address: str) -> None:
    """Raise RuntimeError unless something listens at ``host:port`` (Ray would retry forever)."""
    if address == 'auto' or '://' in address:
        return
    host, _, port = address.rpartition(':')
    try:
        socket.create_connection((host or '127.0.0.1', int(port)), timeout=5).close()
    except ValueError:
        raise RuntimeError(f'{address!r} is not host:port (or auto)') from None
    except OSError as exc:
        raise RuntimeError(f'no Ray cluster answers at {address} '
                           f'({exc.strerror or type(exc).__name__})') from None


class RayExecutor:
    """The tasks on a Ray cluster: one CPU each, as many at a time as the cluster has CPUs."""

    def __init__(self, address: str, function: Callable = evaluate_task):
        """Connect to the cluster at ``address`` (``auto``: the one this machine is in)."""
        try:
            import ray
        except ImportError:
            raise RuntimeError("--ray needs Ray: pip install 'ray[default]' (or this "
                               "package's extra: pip install '.[ray]')") from None
        self._ray = ray
        _check_reachable(address)
        ray.init(address=address, logging_level='WARNING', log_to_driver=False,
                 configure_logging=False)
        self.workers = max(int(ray.cluster_resources().get('CPU', 1)), 1)
        self.where = f'the Ray cluster at {address} ({self.workers} CPUs)'
        # Retried by the caller, as locally: Ray's own retries would count apart.
        self._remote = ray.remote(num_cpus=1, max_retries=0)(function)
        self._refs: Dict[object, str] = {}

    @property
    def free(self) -> int:
        """Return how many more tasks can start now (one per CPU of the cluster)."""
        return max(self.workers - len(self._refs), 0)

    def submit(self, key: str, payload: dict) -> None:
        """Start ``payload`` on the cluster."""
        self._refs[self._remote.remote(payload)] = key

    def next_done(self) -> Outcome:
        """Wait for a task to end; return its outcome."""
        ray = self._ray
        (ref,), _ = ray.wait(list(self._refs), num_returns=1)
        key = self._refs.pop(ref)
        try:
            return key, ray.get(ref), ''
        except ray.exceptions.RayTaskError as exc:
            cause = exc.cause if exc.cause is not None else exc
            return key, None, f'{type(cause).__name__}: {cause}'
        except ray.exceptions.RayError as exc:  # the worker or its node died
            return key, None, f'the worker died ({type(exc).__name__}: ' \
                              f'{str(exc).splitlines()[0] if str(exc) else ""})'

    def close(self) -> None:
        """Cancel what is under way and leave the cluster (which runs on)."""
        for ref in self._refs:
            self._ray.cancel(ref, force=True)
        self._refs = {}
        self._ray.shutdown()
