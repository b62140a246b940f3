"""
What the node records, and when: the node's side of a ``Recorder``.

See doc/operations.md, "Recording".

A query is recorded as one group when its answer goes out: its request as received (raw
bytes, log time = receipt, held until then), its trajectory and its result as published
(the same bytes, publication time), handed to the operating system before they are
published. So a query is never torn across the files of a split recording, nor written
twice, whatever the queue holds when a file is split. Requests still unanswered when the
recording is closed are written then; after a crash they are not in it (every answered
query is). The MCAP ``sequence`` of a request, of its trajectory and of its result is the
query number (1, 2, ... per node run), which pairs them however the answers interleave.

Every file begins with what makes it readable alone (the ``Recorder``'s preamble): the
parameters, the cell file and the roadmap's identity (``recording.contents``) in force
when the file's first query arrived (and those that followed), and the roadmap markers.
Within a file each roadmap load adds its cell file, identity and markers, and the
parameters are attached again whenever they change. A recording that stops by itself (a
full disk, its directory deleted) says so in ``recording_error``, with the number of
answers it has not recorded since, also given as ``recording_lost``. ROS-free: the node
passes topic names and bytes.
"""

from collections import deque
from dataclasses import dataclass, replace
from pathlib import Path
import threading
import time
from typing import Callable, Dict, Mapping, Optional, Sequence, Tuple

from wafer_planner_ros.errors import WaferPlannerError
from wafer_planner_ros.recording.bag import Topic
from wafer_planner_ros.recording.contents import (CELL_ATTACHMENT, LOAD_METADATA,
                                                  PARAMETERS_ATTACHMENT, parameters_file)
from wafer_planner_ros.recording.recorder import bag_name, Limits, Message, Preamble, Recorder

MAX_HELD = 10000
"""Requests held for their answers beyond which the oldest is written alone."""
HISTORY = 16
"""Roadmap loads and parameter versions remembered for the files to come."""


@dataclass(frozen=True)
class Loaded:
    """What a roadmap load adds to a recording."""

    cell_text: bytes
    values: Mapping[str, str]
    """The ``wafer_planner`` metadata record (cell, roadmap hash, nodes, seed, ...)."""
    loaded_ns: int
    markers: bytes = b''
    """The serialised roadmap markers (``markers`` adds them once they are made)."""


def limits_of(settings) -> Limits:
    """Return the recording limits of the node's ``NodeSettings``."""
    return Limits(settings.recording_max_bag_size, settings.recording_max_bag_duration,
                  settings.recording_keep)


class NodeRecording:
    """Start, feed and stop the node's recording; see the module's description."""

    def __init__(self, node_name: str, topics: Sequence[Topic], markers_topic: str,
                 on_error: Callable[[str], None], limits: Callable[[], Limits] = Limits,
                 clock: Callable[[], int] = time.time_ns):
        """
        Remember the topics (``markers_topic`` is one of them); record nothing yet.

        ``limits`` returns the splitting and retention limits in force (asked before each
        query is written); ``clock`` is the time in ns since the epoch.
        """
        self._node_name = node_name
        self._topics = tuple(topics)
        self._markers_topic = markers_topic
        self._on_error = on_error
        self._limits = limits
        self._clock = clock
        self._lock = threading.Lock()
        self._recorder: Optional[Recorder] = None
        self._held: Dict[int, Message] = {}
        """Requests waiting for their answers, by query number, oldest first."""
        self._loads = deque(maxlen=HISTORY)
        self._preamble_saw = (None, None)
        """The last roadmap load and parameters a file's preamble held."""
        self._parameters = deque(maxlen=HISTORY)
        """(log time, ``parameters.yaml``), oldest first."""
        self.last_error = ''
        self.last_directory: Optional[Path] = None

    def start(self, parent: Path) -> Path:
        """Start a new bag under ``parent``; return its directory. Raises ``OSError``."""
        with self._lock:
            if self._recorder is not None and not self._recorder.error:
                return self._recorder.directory
            failed = self._recorder
        if failed is not None:
            failed.close(timeout=1.0)  # a stopped recording's thread ends with it
        directory = Path(parent).expanduser() / bag_name(self._node_name)
        try:  # not under the lock: the preamble needs it, and a dead mount may hang here
            recorder = Recorder(directory, self._topics, self._failed, limits=self._limits,
                                clock=self._clock, preamble=self._preamble)
        except (OSError, WaferPlannerError) as exc:
            reason = getattr(exc, 'strerror', None) or exc
            self.last_error = f'cannot record to {directory}: {reason}'
            raise OSError(self.last_error) from exc
        with self._lock:
            self._recorder, self.last_error, self.last_directory = recorder, '', directory
            # What changed while the first file's preamble was taken goes in after it.
            load, parameters = self._preamble_saw
            if self._loads and self._loads[-1] is not load:
                self._add_loaded(recorder, self._loads[-1])
            if self._parameters and self._parameters[-1] is not parameters:
                when, data = self._parameters[-1]
                recorder.attach(PARAMETERS_ATTACHMENT, data, when)
            recorder.flush()
            return directory

    def stop(self) -> Tuple[Optional[Path], str]:
        """
        Close the bag (``metadata.yaml`` written), with the requests still unanswered.

        Return its directory (None when not recording) and why it could not be closed
        properly ('' when it was).
        """
        with self._lock:
            recorder, self._recorder = self._recorder, None
            held, self._held = list(self._held.values()), {}
        if recorder is None:
            return None, ''
        for message in held:
            recorder.record(*message)
        if recorder.close() is None:
            self.last_error = _error(recorder.status())
            return recorder.directory, self.last_error
        return recorder.directory, ''

    def request(self, topic: str, data: bytes, number: int, info: Mapping) -> None:
        """Hold request ``number`` as received (``info``: rmw's message info, in ns)."""
        recorder = self._recorder
        if recorder is None:
            return
        received = info.get('received_timestamp') or self._clock()
        sent = info.get('source_timestamp') or received
        with self._lock:
            self._held[number] = (topic, data, received, sent, number)
            oldest = self._held.pop(next(iter(self._held))) \
                if len(self._held) > MAX_HELD else None
        if oldest is not None:  # never answered, it seems: written alone rather than held
            recorder.write_now([oldest], flush=False)

    def answer(self, number: int, messages: Sequence[Tuple[str, bytes]]) -> Optional[bool]:
        """
        Record query ``number`` (its request, trajectory and result) before it goes out.

        Return True once a process crash can no longer lose it, False when it goes out
        before it is safe (a stalled disk: it is queued), None when it is not recorded (not
        recording, or the recording has stopped: the recorder counts it as lost).
        """
        recorder = self._recorder
        if recorder is None:
            return None
        with self._lock:
            request = self._held.pop(number, None)
        now = self._clock()
        group = [request] if request is not None else []
        group += [(topic, data, now, now, number) for topic, data in messages]
        safe = recorder.write_now(group)
        return None if safe is False and recorder.error else safe

    def loaded(self, loaded: Loaded) -> None:
        """Record a new roadmap before it serves (and keep it for the files to come)."""
        with self._lock:
            self._loads.append(loaded)
            if self._recorder is not None:
                self._add_loaded(self._recorder, loaded)

    def markers(self, data: bytes) -> None:
        """Record the roadmap markers of the last load."""
        with self._lock:
            if not self._loads:
                return
            self._loads[-1] = replace(self._loads[-1], markers=data)
            if self._recorder is not None:
                now = self._clock()
                self._recorder.record(self._markers_topic, data, now, now, 0)
                self._recorder.flush()

    def parameters(self, values: Mapping[str, object]) -> None:
        """Record the node's parameter values (all of them) as they are from now on."""
        data = parameters_file(self._node_name, values)
        now = self._clock()
        with self._lock:
            self._parameters.append((now, data))
            if self._recorder is not None:
                self._recorder.attach(PARAMETERS_ATTACHMENT, data, now)

    def status(self) -> dict:
        """Return the recording's state (for ``~/get_status`` and ``/diagnostics``)."""
        recorder = self._recorder
        if recorder is None:
            return {'recording': False, 'recording_directory': str(self.last_directory or ''),
                    'recording_error': self.last_error}
        state = recorder.status()
        return {'recording': not state['error'], 'recording_directory': state['directory'],
                'recording_error': _error(state), 'recorded': state['written'],
                'recording_dropped': state['dropped'], 'recording_lost': state['lost'],
                'recording_stalled': state['stalled'], 'recording_file': state['file'],
                'recording_files': state['files'], 'recording_removed': state['removed']}

    def _preamble(self, since: Optional[int]) -> Preamble:
        """
        Return what a new file begins with: the context of every query it may get.

        That is the parameters and the roadmap load in force at ``since`` (the arrival of
        the query it is started for) or at the arrival of the oldest request still held,
        whichever is earlier (now, when neither), the later ones, and the last markers.
        """
        now = self._clock()
        with self._lock:
            moments = [m[2] for m in self._held.values()] + [since if since else now]
            moment = min(moments)
            parameters = _in_force(self._parameters, moment, lambda item: item[0])
            loads = _in_force(self._loads, moment, lambda load: load.loaded_ns)
            self._preamble_saw = (self._loads[-1] if self._loads else None,
                                  self._parameters[-1] if self._parameters else None)
        records = [self._load_records(load, now) for load in loads]
        attachments = [(PARAMETERS_ATTACHMENT, data, when, 'application/yaml')
                       for when, data in parameters] + [cell for cell, _, _ in records]
        metadata = [values for _, values, _ in records]
        markers = [records[-1][2]] if records and records[-1][2] is not None else []
        return Preamble(attachments, metadata, markers)

    def _add_loaded(self, recorder: Recorder, loaded: Loaded) -> None:
        cell, values, markers = self._load_records(loaded, self._clock())
        recorder.attach(*cell)
        recorder.metadata(*values)
        if markers is not None:
            recorder.record(*markers)

    def _load_records(self, load: Loaded, now: int) -> tuple:
        """Return a load's cell attachment, its metadata record, its markers' message (or None)."""
        return ((CELL_ATTACHMENT, load.cell_text, load.loaded_ns, 'application/yaml'),
                (LOAD_METADATA, dict(load.values, loaded_ns=str(load.loaded_ns))),
                (self._markers_topic, load.markers, now, now, 0) if load.markers else None)

    def _failed(self, message: str) -> None:
        self.last_error = message
        self._on_error(message)


def _in_force(history, moment: int, when) -> list:
    """Return the entry of the time-ordered ``history`` in force at ``moment``, and later ones."""
    items = list(history)
    first = 0
    for index, item in enumerate(items):
        if when(item) <= moment:
            first = index
    return items[first:]


def _error(state: Mapping) -> str:
    """Return a failed recording's error with the answers lost since ('' when none)."""
    if not state['error']:
        return ''
    lost = state['lost']
    return f"{state['error']}; {lost} answer{'' if lost == 1 else 's'} not recorded"
