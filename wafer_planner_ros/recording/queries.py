"""
The queries of a recording: each request with its result, trajectory and context.

A request, its trajectory and its result share the MCAP ``sequence`` (the query number, see
``contents``). The context of a query is what was in force when it arrived: the last
roadmap load before it (cell file, roadmap hash, nodes, seed) and the last parameters. The
messages are decoded from the schemas stored in the recording itself (``mcap_ros2``), so no
ROS installation is needed to read them.
"""

from dataclasses import dataclass, field
import functools
import json
from typing import Dict, List, Mapping, Optional, Tuple

from mcap_ros2.decoder import DecoderFactory
import numpy as np

from wafer_planner_ros.cell.model import Cell
from wafer_planner_ros.recording.contents import (CELL_ATTACHMENT, LOAD_METADATA,
                                                  PARAMETERS_ATTACHMENT, read_parameters)
from wafer_planner_ros.recording.reading import Recording

NODE_ONLY_CODES = frozenset(('BUSY', 'TIMEOUT', 'ROADMAP_NOT_READY'))
"""Answers that depend on the node's load at the time, not on the request."""


@dataclass(frozen=True)
class Load:
    """A roadmap load recorded in the bag."""

    loaded_ns: int
    cell_text: bytes
    values: Mapping[str, str]
    """The ``wafer_planner`` metadata record: cell, roadmap_hash, roadmap_nodes, ..."""

    @property
    def roadmap_hash(self) -> str:
        """Return the hash of the roadmap the node planned on."""
        return self.values.get('roadmap_hash', '')

    @functools.cached_property
    def cell(self) -> Cell:
        """Return the recorded cell; raise CellError when it cannot be used."""
        return Cell.from_text(self.cell_text, self.values.get('cell_file', CELL_ATTACHMENT))


@dataclass(frozen=True)
class Trajectory:
    """A recorded trajectory as arrays."""

    joint_names: Tuple[str, ...]
    times: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray
    accelerations: np.ndarray


@dataclass(frozen=True)
class Result:
    """A recorded ``~/result``."""

    level: int
    request_id: str
    message: str
    values: Mapping[str, str]
    published_ns: int


REQUEST_KINDS = ('station', 'joint', 'stop')
"""The kinds of request a recording holds: plan requests by station or joint angles, and
stop requests of a published trajectory."""


@dataclass(frozen=True)
class Query:
    """One request and everything recorded about it."""

    number: int
    kind: str
    """'station', 'joint' or 'stop' (``REQUEST_KINDS``)."""
    topic: str
    received_ns: int
    data: bytes
    """The request's serialised bytes, as received."""
    request: object
    """The decoded request (``std_msgs/String`` or ``trajectory_msgs/JointTrajectory``; a stop
    request is a ``std_msgs/String``)."""
    result: Optional[Result] = None
    trajectory: Optional[Trajectory] = None
    load: Optional[Load] = None
    parameters: Mapping[str, object] = field(default_factory=dict)

    @property
    def code(self) -> str:
        """Return the code of the recorded answer ('' when no answer was recorded)."""
        return self.result.values.get('code', '') if self.result is not None else ''

    @property
    def request_id(self) -> str:
        """Return the request id as answered (or as sent, for an unanswered joint request)."""
        if self.result is not None:
            return self.result.request_id
        return self.request.header.frame_id if self.kind == 'joint' else ''

    @property
    def cycle_time(self) -> Optional[float]:
        """Return the recorded cycle time (s), None for a failed or unanswered query."""
        text = self.result.values.get('cycle_time') if self.result is not None else None
        return float(text) if text else None

    def ends(self) -> Tuple[str, str]:
        """Return the (from, to) labels of the answer (station names or joint lists)."""
        values = self.result.values if self.result is not None else {}
        return values.get('from', ''), values.get('to', '')


def queries(recording: Recording) -> List[Query]:
    """Return the queries of ``recording`` in the order their requests arrived."""
    decode = _decoders(recording)
    loads = sorted(_loads(recording), key=lambda load: load.loaded_ns)
    parameters = sorted(((a.log_time, read_parameters(a.data)) for a in recording.attachments
                         if a.name == PARAMETERS_ATTACHMENT), key=lambda item: item[0])
    requests, results, trajectories = {}, {}, {}
    for message in recording.messages:
        channel = recording.channels[message.channel_id]
        kind = _kind(channel.topic)
        if kind in REQUEST_KINDS:
            requests[message.sequence] = (kind, channel.topic, message)
        elif kind == 'result':
            results[message.sequence] = message
        elif kind == 'trajectory':
            trajectories[message.sequence] = message
    found = []
    for number in sorted(requests, key=lambda n: requests[n][2].log_time):
        kind, topic, message = requests[number]
        received = message.log_time
        result = results.get(number)
        trajectory = trajectories.get(number)
        found.append(Query(
            number=number, kind=kind, topic=topic, received_ns=received, data=message.data,
            request=decode[message.channel_id](message.data),
            result=_result(decode[result.channel_id](result.data), result.log_time)
            if result is not None else None,
            trajectory=_trajectory(decode[trajectory.channel_id](trajectory.data))
            if trajectory is not None else None,
            load=_last(loads, received, lambda load: load.loaded_ns),
            parameters=(_last(parameters, received, lambda item: item[0]) or (0, {}))[1]))
    return found


def _kind(topic: str) -> str:
    for suffix, kind in (('/plan_station_request', 'station'), ('/plan_request', 'joint'),
                         ('/stop_request', 'stop'),
                         ('/result', 'result'), ('/trajectory', 'trajectory')):
        if topic.endswith(suffix):
            return kind
    return ''


def _decoders(recording: Recording) -> Dict[int, object]:
    factory = DecoderFactory()
    decoders = {}
    for channel_id, channel in recording.channels.items():
        decoder = factory.decoder_for(channel.message_encoding,
                                      recording.schemas.get(channel.schema_id))
        if decoder is not None:
            decoders[channel_id] = decoder
    return decoders


def _loads(recording: Recording) -> List[Load]:
    cells = sorted(((a.log_time, a.data) for a in recording.attachments
                    if a.name == CELL_ATTACHMENT), key=lambda item: item[0])
    loads = []
    for record in recording.metadata:
        if record.name != LOAD_METADATA:
            continue
        loaded = int(record.metadata.get('loaded_ns', 0))
        cell = _last(cells, loaded, lambda item: item[0])
        loads.append(Load(loaded, cell[1] if cell else b'', dict(record.metadata)))
    return loads


def _last(items, moment: int, when):
    """Return the last of the time-sorted ``items`` at or before ``moment`` (or None)."""
    chosen = None
    for item in items:
        if when(item) > moment:
            break
        chosen = item
    return chosen


def _result(status, published: int) -> Result:
    level = status.level
    return Result(level=level if isinstance(level, int) else ord(level),
                  request_id=status.name, message=status.message,
                  values={kv.key: kv.value for kv in status.values}, published_ns=published)


def _trajectory(message) -> Trajectory:
    points = message.points

    def rows(name: str) -> np.ndarray:
        return np.array([list(getattr(p, name)) for p in points], float).reshape(
            len(points), len(message.joint_names))
    times = np.array([p.time_from_start.sec + 1e-9 * p.time_from_start.nanosec
                      for p in points], float)
    return Trajectory(tuple(message.joint_names), times, rows('positions'),
                      rows('velocities'), rows('accelerations'))


def label_configuration(label: str, cell) -> Optional[np.ndarray]:
    """Return the joint configuration of a ``from``/``to`` label (a station's first)."""
    if not label:
        return None
    if label in cell.stations:
        return cell.stations[label].configs[0].q
    try:
        values = np.asarray(json.loads(label), float).reshape(-1)
    except (ValueError, TypeError):
        return None
    return values if values.shape == (len(cell.robot.joint_names),) else None


def short_label(label: str, decimals: int = 2) -> str:
    """Return a ``from``/``to`` label for a table: joint lists rounded, names as they are."""
    if not label.startswith('['):
        return label
    try:
        values = [float(v) for v in json.loads(label)]
    except (ValueError, TypeError):
        return label
    return '[' + ', '.join(f'{v:.{decimals}f}' for v in values) + ']'
