"""
The files of a recording: when the current one is finished, and what the next begins with.

Splitting (``recorder.Limits``, read again before every group, so they may change at run
time): the messages of one ``Recorder.write_now`` call are a group, and groups are never
split across files. Before a group is written, the current file is finished and the next
one started when the group would take the finished file past ``max_bag_size``
(``projected_size``, an upper bound) or the file was opened ``max_bag_duration`` ago or
more (by the clock), unless the file holds no group yet. Every new file first gets the
preamble (what makes it readable alone: the node's cell file, roadmap load, parameters and
markers). Before a new file is started, ``retention.prune`` removes the oldest files of the
node's recordings beyond ``keep`` (counting the new one). Syncing and closing the finished
file, and rewriting the ``metadata.yaml`` of older recordings that lost files, are slow:
they are handed back (``finished``) for the recorder's thread to do.
"""

import logging
from pathlib import Path
from typing import Callable, Optional, Sequence, Tuple

from wafer_planner_ros.recording import retention
from wafer_planner_ros.recording.bag import BagWriter

logger = logging.getLogger(__name__)


class Splitter:
    """Write a recording's groups into its files, a new file when one is due (the module's)."""

    def __init__(self, writer: BagWriter, limits: Callable, clock: Callable[[], int],
                 preamble: Callable, finished: Callable[[object, Tuple[Path, ...]], None]):
        """
        Write through ``writer``, its first file not yet begun (``begin_file``).

        ``limits()``: the ``recorder.Limits`` in force. ``clock``: now, in ns (the age of a
        file). ``preamble(since)``: the ``recorder.Preamble`` a new file begins with, where
        ``since`` is the earliest log time of the group it is started for (None for the
        first file). ``finished(stream, touched)``: called with each finished file's stream
        and the older bags whose ``metadata.yaml`` to rewrite, once the next file is begun.
        The caller holds the writer's lock around every call.
        """
        self._writer = writer
        self._limits = limits
        self._clock = clock
        self._preamble = preamble
        self._finished = finished
        self.removed = 0
        """Files removed by retention."""
        self._groups = 0
        """Groups written into the current file."""
        self._opened = 0
        """When the current file was started (``clock``)."""

    def write_group(self, messages: Sequence, group: bool = True) -> None:
        """Write ``messages``; a group first starts a new file when the current one is due."""
        if group and messages and self._groups and self._due(messages):
            self._split(min(message[2] for message in messages))
        for message in messages:
            self._writer.write(*message)
        self._groups += group and bool(messages)

    def _due(self, messages: Sequence) -> bool:
        """Return whether ``messages`` are to begin a new file (the module's description)."""
        limits = self._limits()
        if limits.max_bag_duration > 0 and \
                self._clock() - self._opened >= limits.max_bag_duration * 1e9:
            return True
        return limits.max_bag_size > 0 and limits.max_bag_size < \
            self._writer.projected_size(len(message[1]) for message in messages)

    def _split(self, since: int) -> None:
        """Finish the current file, prune, and begin the next for a group from ``since``."""
        limits = self._limits()
        finished, name = self._writer.finish_file(), self._writer.path
        size = finished.tell()
        if limits.max_bag_size and size > limits.max_bag_size:
            logger.warning('%s: %d bytes, over recording.max_bag_size (%d): its first query '
                           'alone did not fit', name, size, limits.max_bag_size)
        touched = self.prune(limits, room=limits.keep - 1)
        self._writer.next_file()
        self.begin_file(since)
        self._finished(finished, touched)

    def begin_file(self, since: Optional[int]) -> None:
        """Write the preamble into the new current file and hand it to the system."""
        self._opened, self._groups = self._clock(), 0
        preamble = self._preamble(since)
        for attachment in preamble.attachments:
            self._writer.attach(*attachment)
        for name, values in preamble.metadata:
            self._writer.metadata(name, values)
        for message in preamble.messages:
            self._writer.write(*message)
        self._writer.flush()

    def prune(self, limits, room: Optional[int] = None,
              protect: Optional[Path] = None) -> Tuple[Path, ...]:
        """Apply ``keep``; return the older bags whose ``metadata.yaml`` must be rewritten."""
        if limits.keep <= 0:
            return ()
        removed, touched = retention.prune(
            self._writer.directory, limits.keep if room is None else room, protect)
        self.removed += len(removed)
        return tuple(touched)
