"""
Reading a recording record by record, including one cut off by a crash.

A bag whose writer was killed has no summary, index or footer, and no ``metadata.yaml``:
seeking readers (``rosbags``, ``ros2 bag``) refuse it. Read linearly, it yields every record
up to the last one written whole (``recover`` makes it complete).
"""

from dataclasses import dataclass, field
from pathlib import Path
import struct
from typing import Dict, List

from mcap.exceptions import McapError
from mcap.records import Attachment, Channel, Footer, Header, Message, Metadata, Schema
from mcap.stream_reader import StreamReader

from wafer_planner_ros.errors import WaferPlannerError
from wafer_planner_ros.recording.bag import bag_file, Topic


class RecordingError(WaferPlannerError):
    """A recording that cannot be read at all; names the file and the reason."""


@dataclass
class Recording:
    """Every record of one MCAP file, in file order."""

    path: Path
    profile: str = ''
    library: str = ''
    schemas: Dict[int, Schema] = field(default_factory=dict)
    channels: Dict[int, Channel] = field(default_factory=dict)
    messages: List[Message] = field(default_factory=list)
    attachments: List[Attachment] = field(default_factory=list)
    metadata: List[Metadata] = field(default_factory=list)
    complete: bool = False
    """True when the file ends with its footer (closed cleanly)."""
    cut: str = ''
    """Why reading stopped before a footer (empty when complete)."""

    def topics(self) -> List[Topic]:
        """Return the recorded topics, in channel order."""
        return [Topic.from_channel(c.topic, self.schemas[c.schema_id].name, c.metadata)
                for c in self.channels.values()]

    def counts(self) -> Dict[str, int]:
        """Return the number of messages per topic."""
        counts = {c.topic: 0 for c in self.channels.values()}
        for message in self.messages:
            counts[self.channels[message.channel_id].topic] += 1
        return counts


def mcap_file(path) -> Path:
    """Return the MCAP file of a bag directory (or ``path`` itself when it is a file)."""
    path = Path(path)
    if path.is_file():
        return path
    if not path.is_dir():
        raise RecordingError(f'{path}: no such recording (a bag directory or .mcap file)')
    expected = bag_file(path)
    if expected.is_file():
        return expected
    found = sorted(path.glob('*.mcap'))
    if len(found) != 1:
        raise RecordingError(f'{path}: expected one .mcap file, found {len(found)}')
    return found[0]


def read(path) -> Recording:
    """Read every record of a recording, stopping quietly where a crash cut it off."""
    file = mcap_file(path)
    recording = Recording(file)
    try:
        with open(file, 'rb') as stream:
            for record in StreamReader(stream, validate_crcs=True).records:
                _collect(recording, record)
    except (McapError, struct.error, ValueError, EOFError) as exc:
        if not recording.schemas and not recording.profile:
            raise RecordingError(f'{file}: not a readable MCAP file ({exc!r})') from exc
        recording.cut = f'{type(exc).__name__} {exc}'.strip()
    except OSError as exc:
        raise RecordingError(f'{file}: {exc.strerror or exc}') from exc
    if not recording.complete and not recording.cut:
        recording.cut = 'the file ends before its footer'
    return recording


def _collect(recording: Recording, record) -> None:
    if isinstance(record, Message):
        recording.messages.append(record)
    elif isinstance(record, Schema):
        recording.schemas[record.id] = record
    elif isinstance(record, Channel):
        recording.channels[record.id] = record
    elif isinstance(record, Attachment):
        recording.attachments.append(record)
    elif isinstance(record, Metadata):
        if record.name != 'rosbag2':
            recording.metadata.append(record)
    elif isinstance(record, Header):
        recording.profile, recording.library = record.profile, record.library
    elif isinstance(record, Footer):
        recording.complete = True
