"""
The recorder: a ``BagWriter`` behind a queue and a thread of its own (SPEC section 6).

The node hands it bytes that are already serialised; every call returns at once, so disk
I/O never holds up planning. ``flush`` marks a durability point and returns an event: it is
set once everything queued before it has been handed to the operating system (a process
crash, even SIGKILL, then loses none of it); the file is ``fsync``-ed right after, against
power loss. The node records a query's trajectory and result, waits (briefly, bounded) for
that event, and only then publishes: no query is answered that a crash could lose.
A write error (a full disk, a directory that vanished) stops the recording, is reported
through ``on_error`` and ``status()``, and leaves the bag readable up to its last flush
(``wafer-recover`` completes it). Planning goes on regardless.
"""

from collections import deque
import logging
from pathlib import Path
import threading
import time
from typing import Callable, Mapping, Optional, Sequence

from wafer_planner_ros.recording.bag import BagWriter, Topic

logger = logging.getLogger(__name__)

MAX_PENDING = 20000
"""Queued items beyond which new ones are dropped (and counted) rather than held."""


def bag_name(node_name: str, when: Optional[float] = None) -> str:
    """Return ``<node>_<UTC time>`` (to the microsecond), the name of a new bag directory."""
    when = time.time() if when is None else when
    stamp = time.strftime('%Y_%m_%d-%H_%M_%S', time.gmtime(when))
    return f'{node_name}_{stamp}_{int(when % 1 * 1e6):06d}'


class Recorder:
    """Record to a new bag in ``directory`` from a thread; see the module's description."""

    def __init__(self, directory: Path, topics: Sequence[Topic],
                 on_error: Optional[Callable[[str], None]] = None, opener=open):
        """Create the bag (raises ``OSError`` when it cannot) and start the thread."""
        self._writer = BagWriter(directory, topics, opener)
        self.directory = self._writer.directory
        self._on_error = on_error
        self._queue = deque()
        self._wake = threading.Condition()
        self._closing = False
        self.error = ''
        self.dropped = 0
        self.written = 0
        self.flushed = 0
        """Messages known to be on the disk."""
        self._thread = threading.Thread(target=self._run, name='wafer_planner_recorder',
                                        daemon=True)
        self._thread.start()

    # -------------------------------------------------------------- producers (any thread)

    def record(self, topic: str, data: bytes, log_time: int, publish_time: int,
               sequence: int = 0) -> None:
        """Queue one serialised message (times in ns since the epoch)."""
        self._put(('message', topic, data, log_time, publish_time, sequence))

    def attach(self, name: str, data: bytes, log_time: int,
               media_type: str = 'application/yaml') -> None:
        """Queue an attachment."""
        self._put(('attach', name, data, log_time, media_type))

    def metadata(self, name: str, values: Mapping[str, str]) -> None:
        """Queue a metadata record."""
        self._put(('metadata', name, dict(values)))

    def flush(self) -> threading.Event:
        """Queue a durability point; return the event set when it has been reached."""
        reached = threading.Event()
        self._put(('flush', reached))
        return reached

    def close(self, timeout: float = 30.0) -> Optional[Path]:
        """
        Write what is queued, finish the bag and write ``metadata.yaml``; return its path.

        Returns None when the bag could not be finished (see ``error``).
        """
        with self._wake:
            self._closing = True
            self._wake.notify()
        self._thread.join(timeout)
        if self._thread.is_alive():
            self._fail(f'recording did not finish within {timeout:.0f} s; '
                       f'{len(self._queue)} items were not written')
            return None
        return None if self.error else self.directory / 'metadata.yaml'

    def status(self) -> dict:
        """Return the recording's state for status and diagnostics."""
        return {'directory': str(self.directory), 'written': self.written,
                'flushed': self.flushed, 'pending': len(self._queue),
                'dropped': self.dropped, 'error': self.error}

    def _put(self, item) -> None:
        with self._wake:
            if self.error or self._closing or len(self._queue) >= MAX_PENDING:
                _discard([item])
                self.dropped += item[0] == 'message'
                return
            self._queue.append(item)
            self._wake.notify()

    # -------------------------------------------------------------- the thread

    def _run(self) -> None:
        writer = self._writer
        while True:
            with self._wake:
                while not self._queue and not self._closing:
                    self._wake.wait()
                items = list(self._queue)
                self._queue.clear()
                closing = self._closing and not items
            done = 0
            try:
                unsynced = False
                for item in items:
                    unsynced = self._apply(writer, item) or unsynced
                    done += 1
                if unsynced:  # once per batch: fsync takes ~0.3 ms
                    writer.sync()
                    self.flushed = self.written
                if closing:
                    writer.close()
                    return
            except Exception as exc:  # noqa: B902 - any failure stops the recording only
                lost = items[done:]
                with self._wake:
                    self.dropped += sum(1 for item in lost if item[0] == 'message')
                _discard(lost)
                writer.abandon()
                self._fail(f'recording to {writer.path} failed: {exc}')
                return

    def _apply(self, writer: BagWriter, item) -> bool:
        """Apply one queued item; return True after a flush (the file then needs a sync)."""
        kind = item[0]
        if kind == 'message':
            writer.write(*item[1:])
            self.written += 1
        elif kind == 'flush':
            writer.flush()
            item[1].set()
            return True
        elif kind == 'attach':
            writer.attach(*item[1:])
        else:
            writer.metadata(*item[1:])
        return False

    def _fail(self, message: str) -> None:
        with self._wake:
            self.error = message
            self.dropped += sum(1 for item in self._queue if item[0] == 'message')
            _discard(self._queue)
            self._queue.clear()
        logger.error(message)
        if self._on_error is not None:
            self._on_error(message)


def _discard(items) -> None:
    """Release whoever waits on the flush events among ``items`` (nothing will be written)."""
    for item in items:
        if item[0] == 'flush':
            item[1].set()
