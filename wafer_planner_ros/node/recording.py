"""
What the node records, and when (SPEC section 6): the node's side of a ``Recorder``.

Every request is recorded as received (raw bytes, receipt time), every trajectory and
result as published (the same bytes, publication time), the roadmap markers once per
roadmap. The MCAP ``sequence`` of a request, of its trajectory and of its result is the
query number (1, 2, ... per node run), which pairs them however the answers interleave.
Each roadmap load adds the cell file and the roadmap's identity, and the parameters are
attached whenever they change (``recording.contents``), so a recording is self-contained.
A recording that stops by itself (a full disk, its directory deleted) says so in
``recording_error``, with the number of answers it has not recorded since, also given as
``recording_lost``. ROS-free: the node passes topic names and bytes.
"""

from dataclasses import dataclass, replace
from pathlib import Path
import threading
import time
from typing import Callable, Mapping, Optional, Sequence, Tuple

from wafer_planner_ros.errors import WaferPlannerError
from wafer_planner_ros.recording.bag import Topic
from wafer_planner_ros.recording.contents import (CELL_ATTACHMENT, LOAD_METADATA,
                                                  PARAMETERS_ATTACHMENT, parameters_file)
from wafer_planner_ros.recording.recorder import bag_name, Recorder


@dataclass(frozen=True)
class Loaded:
    """What a roadmap load adds to a recording."""

    cell_text: bytes
    values: Mapping[str, str]
    """The ``wafer_planner`` metadata record (cell, roadmap hash, nodes, seed, ...)."""
    loaded_ns: int
    markers: bytes = b''
    """The serialised roadmap markers (``markers`` adds them once they are made)."""


class NodeRecording:
    """Start, feed and stop the node's recording; see the module's description."""

    def __init__(self, node_name: str, topics: Sequence[Topic], markers_topic: str,
                 on_error: Callable[[str], None]):
        """Remember the topics (``markers_topic`` is one of them); record nothing yet."""
        self._node_name = node_name
        self._topics = tuple(topics)
        self._markers_topic = markers_topic
        self._on_error = on_error
        self._lock = threading.Lock()
        self._recorder: Optional[Recorder] = None
        self._loaded: Optional[Loaded] = None
        self._parameters: Optional[bytes] = None
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
        try:  # not under the lock: the worker needs it, and a dead mount may hang here
            recorder = Recorder(directory, self._topics, self._failed)
        except (OSError, WaferPlannerError) as exc:
            reason = getattr(exc, 'strerror', None) or exc
            self.last_error = f'cannot record to {directory}: {reason}'
            raise OSError(self.last_error) from exc
        with self._lock:
            self._recorder, self.last_error, self.last_directory = recorder, '', directory
            if self._parameters is not None:
                recorder.attach(PARAMETERS_ATTACHMENT, self._parameters, time.time_ns())
            if self._loaded is not None:
                self._add_loaded(recorder, self._loaded)
            recorder.flush()
            return directory

    def stop(self) -> Tuple[Optional[Path], str]:
        """
        Close the bag (``metadata.yaml`` written).

        Return its directory (None when not recording) and why it could not be closed
        properly ('' when it was).
        """
        with self._lock:
            recorder, self._recorder = self._recorder, None
        if recorder is None:
            return None, ''
        if recorder.close() is None:
            self.last_error = _error(recorder.status())
            return recorder.directory, self.last_error
        return recorder.directory, ''

    def request(self, topic: str, data: bytes, number: int, info: Mapping) -> None:
        """Record request ``number`` as received (``info``: rmw's message info, in ns)."""
        recorder = self._recorder
        if recorder is not None:
            received = info.get('received_timestamp') or time.time_ns()
            sent = info.get('source_timestamp') or received
            recorder.write_now([(topic, data, received, sent, number)], flush=False)

    def answer(self, number: int, messages: Sequence[Tuple[str, bytes]]) -> Optional[bool]:
        """
        Record the answer to query ``number`` (its trajectory and result) before it goes out.

        Return True once a process crash can no longer lose it, False when it goes out
        before it is safe (a stalled disk: it is queued), None when it is not recorded (not
        recording, or the recording has stopped: the recorder counts it as lost).
        """
        recorder = self._recorder
        if recorder is None:
            return None
        now = time.time_ns()
        safe = recorder.write_now([(topic, data, now, now, number) for topic, data in messages])
        return None if safe is False and recorder.error else safe

    def loaded(self, loaded: Loaded) -> None:
        """Record a new roadmap before it serves (and keep it for a bag started later)."""
        with self._lock:
            self._loaded = loaded
            if self._recorder is not None:
                self._add_loaded(self._recorder, loaded)

    def markers(self, data: bytes) -> None:
        """Record the roadmap markers of the last load."""
        with self._lock:
            if self._loaded is None:
                return
            self._loaded = replace(self._loaded, markers=data)
            if self._recorder is not None:
                now = time.time_ns()
                self._recorder.record(self._markers_topic, data, now, now, 0)
                self._recorder.flush()

    def parameters(self, values: Mapping[str, object]) -> None:
        """Record the node's parameter values (all of them) as they are from now on."""
        data = parameters_file(self._node_name, values)
        with self._lock:
            self._parameters = data
            if self._recorder is not None:
                self._recorder.attach(PARAMETERS_ATTACHMENT, data, time.time_ns())

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
                'recording_stalled': state['stalled']}

    def _add_loaded(self, recorder: Recorder, loaded: Loaded) -> None:
        recorder.attach(CELL_ATTACHMENT, loaded.cell_text, loaded.loaded_ns)
        recorder.metadata(LOAD_METADATA, dict(loaded.values, loaded_ns=str(loaded.loaded_ns)))
        if loaded.markers:
            now = time.time_ns()
            recorder.record(self._markers_topic, loaded.markers, now, now, 0)

    def _failed(self, message: str) -> None:
        self.last_error = message
        self._on_error(message)


def _error(state: Mapping) -> str:
    """Return a failed recording's error with the answers lost since ('' when none)."""
    if not state['error']:
        return ''
    lost = state['lost']
    return f"{state['error']}; {lost} answer{'' if lost == 1 else 's'} not recorded"
