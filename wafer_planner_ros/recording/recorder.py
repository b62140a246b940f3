"""
The recorder: one ``BagWriter``, a lock, and a thread for the slow work.

Two ways in, one file order:

- ``write_now`` (the node's executor: each query's request, trajectory and result together,
  before the answer is published) writes in the calling thread and, with ``flush``,
  hands everything to the operating system before it returns: once it returns True a
  process crash, even SIGKILL, cannot lose those messages. Writing in place is quick;
  handing the bytes to another thread and waiting for it is slow as soon as a planning
  thread holds the GIL.
- ``record``, ``attach`` and ``metadata`` (the worker: roadmap markers, the cell file) only
  queue; the thread writes them. Queued items are written before any later ``write_now``.

Splitting (``Limits``, read again before every group, so they may change at run time) is
``recording.splitting``'s: the messages of one ``write_now`` call are a group, never split
across files; a new file begins with the ``preamble``, and the oldest files beyond ``keep``
are removed. Syncing and closing a finished file, and rewriting the ``metadata.yaml`` of
older recordings that lost files, are left to the thread.

The thread also ``fsync``-s the file after every flush, against power loss. When a sync
has hung for ``STALL`` seconds, or the writer lock cannot be had in that time, the disk is
taken as stalled: ``write_now`` then queues its messages and returns False at once, so
answers are never held up by a stuck disk (the caller counts them). A write error (a full
disk, an unwritable directory) stops the recording, is reported through ``on_error``
and ``status()``, and leaves the bag readable up to its last flush (``wafer-recover``
completes it). So does a deleted file (its directory removed): Linux takes writes to it
without complaint, so every write, and ``status()``, checks that it is still there (cheaply:
``BagWriter.deleted``, which does not look on network filesystems).
Planning goes on regardless. Messages are counted ``written`` only once the file was found
still there after them; ``lost`` counts the answers (``write_now`` with ``flush``) that
did not reach the file because the recording had stopped, or failed while they waited.
"""

from collections import deque
from dataclasses import dataclass
import enum
import logging
from pathlib import Path
import threading
import time
from typing import Callable, Mapping, Optional, Sequence, Tuple, Union

from wafer_planner_ros.recording import retention
from wafer_planner_ros.recording.bag import BagWriter, sync_and_close, Topic
from wafer_planner_ros.recording.splitting import Splitter

logger = logging.getLogger(__name__)

MAX_PENDING = 20000
"""Queued items beyond which new ones are dropped (and counted) rather than held."""
STALL = 0.25
"""Seconds after which a hung sync or a held writer lock counts as a stalled disk."""

Message = Tuple[str, bytes, int, int, int]
"""(topic, serialised bytes, log time ns, publish time ns, sequence)."""


@dataclass(frozen=True)
class Limits:
    """When a bag is split into a new file, and how many files are kept (0: no limit)."""

    max_bag_size: int = 0
    """Bytes a file may take, finished; 0: no split by size."""
    max_bag_duration: float = 0.0
    """Seconds after the opening of a file from which it takes no more groups; 0: never."""
    keep: int = 0
    """Files of the node's recordings kept in the recording directory; 0: all."""


@dataclass(frozen=True)
class Preamble:
    """What a new file of the bag begins with, so that it can be read alone."""

    attachments: Sequence[Tuple[str, bytes, int, str]] = ()
    """(name, data, log time, media type)."""
    metadata: Sequence[Tuple[str, Mapping[str, str]]] = ()
    """(name, values)."""
    messages: Sequence[Message] = ()


class _Item(enum.Enum):
    """What the writer thread's queue holds: (kind, its arguments...)."""

    MESSAGE = enum.auto()
    """(messages, whether they are a group: ``write_now``'s, kept in one file, may split)."""
    FLUSH = enum.auto()
    """(an answer's, or not): a durability point."""
    ATTACH = enum.auto()
    """(name, data, log time, media type)."""
    METADATA = enum.auto()
    """(name, values)."""


class _Deleted(OSError):
    """The bag's file was deleted while it was being written."""


def bag_name(node_name: str, when: Optional[float] = None) -> str:
    """Return ``<node>_<UTC time>`` (to the microsecond), the name of a new bag directory."""
    when = time.time() if when is None else when
    stamp = time.strftime('%Y_%m_%d-%H_%M_%S', time.gmtime(when))
    return f'{node_name}_{stamp}_{int(when % 1 * 1e6):06d}'


class Recorder:
    """Record to a new bag in ``directory``; see the module's description."""

    def __init__(self, directory: Path, topics: Sequence[Topic],
                 on_error: Optional[Callable[[str], None]] = None, opener=open,
                 limits: Union[Limits, Callable[[], Limits]] = Limits(),
                 clock: Callable[[], int] = time.time_ns,
                 preamble: Optional[Callable[[Optional[int]], Preamble]] = None):
        """
        Create the bag (raises ``OSError`` when it cannot) and start the thread.

        ``limits``: the limits, or a function returning those in force. ``clock``: now, in
        ns (the age of a file). ``preamble(since)``: what a new file begins with, where
        ``since`` is the earliest log time of the group it is started for (None for the
        first file).
        """
        self._limits = limits if callable(limits) else (lambda: limits)
        self._writer = BagWriter(directory, topics, opener)
        self.directory = self._writer.directory
        self._on_error = on_error
        self._lock = threading.Lock()
        """Held while the writer is used."""
        self._queue = deque()
        self._wake = threading.Condition()
        """
        Guards the queue, ``_sync_wanted``, ``_closing``, ``error`` and the counters.

        ``_sync_began`` is written by the thread alone and read without it by ``stalled``
        (one float: a stale read only delays the verdict by a write); ``error`` is also
        read without it as a first test (it only ever goes from '' to a message, once).
        """
        self._sync_wanted = False
        self._sync_began: Optional[float] = None
        self._closing = False
        self.error = ''
        self.dropped = 0
        """Messages not written (the recording stopped, or the queue was full)."""
        self.lost = 0
        """Answers (``write_now`` with ``flush``) not written, as ``dropped``."""
        self.written = 0
        self._chores = deque()
        """What the thread does outside the writer lock after a split: (the finished
        file's stream or None, the older bags whose metadata.yaml to rewrite)."""
        self._files = Splitter(
            self._writer, self._limits, clock,
            preamble if preamble is not None else (lambda since: Preamble()), self._finished)
        try:
            touched = self._files.prune(self._limits(), protect=self._writer.path)
            if touched:
                self._chores.append((None, touched))
            self._files.begin_file(None)
        except Exception:
            self._writer.abandon()
            raise
        self._thread = threading.Thread(target=self._run, name='wafer_planner_recorder',
                                        daemon=True)
        self._thread.start()

    # -------------------------------------------------------------- the executor: in place

    def write_now(self, messages: Sequence[Message], flush: bool = True) -> bool:
        """
        Write ``messages`` in this thread (after anything queued); return True when done.

        With ``flush`` they are handed to the operating system before it returns. Returns
        False, having queued them, when the disk is stalled; False, dropping them, when the
        recording has failed or is closing.
        """
        if self.error or self._closing:
            self._count_dropped(len(messages), flush)
            return False
        if not self.stalled() and self._lock.acquire(timeout=STALL):
            try:
                if self.error:  # failed while this thread waited
                    self._count_dropped(len(messages), flush)
                    return False
                self._drain()
                self._files.write_group(messages)
                if flush:
                    self._writer.flush()
                self._check()
                self._count_written(len(messages))
            except Exception as exc:  # noqa: B902 - any failure stops the recording only
                self._count_dropped(len(messages), flush)
                self._fail(exc)
                return False
            finally:
                self._lock.release()
            if flush:
                self._want_sync()
            return True
        # A stalled disk: the thread writes them when it can.
        self._put((_Item.MESSAGE, tuple(messages), True))
        if flush:
            self._put((_Item.FLUSH, True))
        return False

    def stalled(self) -> bool:
        """Return True while a sync has been hanging for more than ``STALL`` seconds."""
        began = self._sync_began
        return began is not None and time.monotonic() - began > STALL

    @property
    def removed(self) -> int:
        """Return how many files retention removed."""
        return self._files.removed

    # -------------------------------------------------------------- any thread: queued

    def record(self, topic: str, data: bytes, log_time: int, publish_time: int,
               sequence: int = 0) -> None:
        """Queue one serialised message (times in ns since the epoch); it never splits."""
        self._put((_Item.MESSAGE, ((topic, data, log_time, publish_time, sequence),), False))

    def attach(self, name: str, data: bytes, log_time: int,
               media_type: str = 'application/yaml') -> None:
        """Queue an attachment."""
        self._put((_Item.ATTACH, name, data, log_time, media_type))

    def metadata(self, name: str, values: Mapping[str, str]) -> None:
        """Queue a metadata record."""
        self._put((_Item.METADATA, name, dict(values)))

    def flush(self) -> None:
        """Queue a durability point: a flush, then a sync."""
        self._put((_Item.FLUSH, False))

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
            self._fail(TimeoutError(f'recording did not finish within {timeout:.0f} s; '
                                    f'{len(self._queue)} items were not written'))
            return None
        return None if self.error else self.directory / 'metadata.yaml'

    def status(self) -> dict:
        """Return the recording's state for status and diagnostics (after ``check``)."""
        self.check()
        with self._wake:
            return {'directory': str(self.directory), 'written': self.written,
                    'pending': len(self._queue), 'dropped': self.dropped, 'lost': self.lost,
                    'stalled': self.stalled(), 'error': self.error,
                    'file': str(self._writer.path), 'files': len(self._writer.files),
                    'removed': self.removed}

    def check(self) -> None:
        """Stop the recording if its file was deleted; never waits for a write under way."""
        if self.error or not self._lock.acquire(blocking=False):
            return  # the write under way checks when it is done
        try:
            if not self.error:
                self._check()
        except _Deleted as exc:
            self._fail(exc)
        finally:
            self._lock.release()

    def _check(self) -> None:
        """Raise ``_Deleted`` if the file was deleted (the writer lock held)."""
        if self._writer.deleted():
            raise _Deleted(f'{self.directory} was deleted')

    def _put(self, item) -> None:
        with self._wake:
            if self.error or self._closing or len(self._queue) >= MAX_PENDING:
                self._tally_dropped([item])
                return
            self._queue.append(item)
            self._wake.notify()

    def _want_sync(self) -> None:
        with self._wake:
            self._sync_wanted = True
            self._wake.notify()

    def _count_written(self, count: int) -> None:
        with self._wake:
            self.written += count

    def _count_dropped(self, count: int, answer: bool = False) -> None:
        with self._wake:
            self.dropped += count
            self.lost += answer

    def _tally_dropped(self, items) -> None:
        """Count the messages and answers among queued ``items`` as dropped (``_wake`` held)."""
        self.dropped += sum(len(item[1]) for item in items if item[0] is _Item.MESSAGE)
        self.lost += sum(1 for item in items if item[0] is _Item.FLUSH and item[1])

    def _finished(self, finished, touched: Tuple[Path, ...]) -> None:
        """Hand a finished file's stream and the bags to rewrite to the thread (a split)."""
        with self._wake:
            self._chores.append((finished, touched))
            self._wake.notify()

    # -------------------------------------------------------------- the thread

    def _run(self) -> None:
        while True:
            with self._wake:
                while not (self._queue or self._sync_wanted or self._closing or self._chores):
                    self._wake.wait()
                closing = self._closing
                sync, self._sync_wanted = self._sync_wanted, False
            try:
                with self._lock:
                    if self.error:
                        return
                    sync = self._drain() or sync
                self._do_chores()
                if closing:
                    with self._lock:
                        if not self.error:
                            self._writer.close()
                    return
                if sync:
                    self._sync_began = time.monotonic()
                    self._writer.sync()  # outside the lock: writes may go on meanwhile
                    self._sync_began = None
            except Exception as exc:  # noqa: B902 - any failure stops the recording only
                self._fail(exc)
                return

    def _do_chores(self) -> None:
        """Sync and close finished files; rewrite the metadata of pruned older bags."""
        while True:
            with self._wake:
                if not self._chores:
                    return
                finished, touched = self._chores.popleft()
            if finished is not None:
                self._sync_began = time.monotonic()
                try:
                    sync_and_close(finished)  # a failure stops the recording, as any write's
                finally:
                    self._sync_began = None
            for bag in touched:
                try:
                    retention.rewrite_metadata(bag)
                except Exception as exc:  # noqa: B902 - that bag is only less readable
                    logger.warning('retention: %s/metadata.yaml not rewritten: %s', bag, exc)

    def _drain(self) -> bool:
        """Write every queued item (the writer lock held); return True after a flush."""
        with self._wake:
            items = list(self._queue)
            self._queue.clear()
        if not items:
            return False
        flushed, checked = False, 0
        try:
            for done, item in enumerate(items, 1):
                kind = item[0]
                if kind is _Item.MESSAGE:
                    self._files.write_group(*item[1:])
                elif kind is _Item.FLUSH:
                    self._writer.flush()
                    flushed = True
                    checked = self._confirm(items, checked, done)
                elif kind is _Item.ATTACH:
                    self._writer.attach(*item[1:])
                else:
                    self._writer.metadata(*item[1:])
            self._confirm(items, checked, len(items))
        except Exception:
            with self._wake:  # what was not in the file at its last check did not reach it
                self._tally_dropped(items[checked:])
            raise
        return flushed

    def _confirm(self, items, checked: int, done: int) -> int:
        """Count ``items[checked:done]`` written once the file is still there; return done."""
        self._check()
        self._count_written(sum(len(item[1]) for item in items[checked:done]
                                if item[0] is _Item.MESSAGE))
        return done

    def _fail(self, exc: BaseException) -> None:
        message = f'recording stopped: {exc}' if isinstance(exc, _Deleted) \
            else f'recording to {self._writer.path} failed: {exc}'
        with self._wake:
            if self.error:
                return
            self.error = message
            self._tally_dropped(self._queue)
            self._queue.clear()
            chores, self._chores = list(self._chores), deque()
            self._wake.notify()
        for finished, _ in chores:  # finished, not yet synced: close them all the same
            try:
                if finished is not None:
                    finished.close()
            except OSError:
                pass
        self._writer.abandon()
        logger.error(message)
        if self._on_error is not None:
            self._on_error(message)
