"""
Reading a recording record by record, including one cut off by a crash, and recovering it.

A bag whose writer was killed has no summary, index or footer, and no ``metadata.yaml``:
seeking readers (``rosbags``, ``ros2 bag``) refuse it. Read linearly, it yields every record
up to the last one written whole; ``recover`` rewrites those records into a complete,
indexed file and writes ``metadata.yaml``, keeping the cut file beside it.
"""

from dataclasses import dataclass, field
import os
from pathlib import Path
import struct
from typing import Dict, List

from mcap.exceptions import McapError
from mcap.records import Attachment, Channel, Footer, Header, Message, Metadata, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer

from wafer_planner_ros.errors import WaferPlannerError
from wafer_planner_ros.recording.bag import (bag_file, METADATA_FILE, metadata_yaml, Topic,
                                             write_metadata_file)

DAMAGED_SUFFIX = '.cut'
"""Appended to the name of the file ``recover`` replaced."""


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


def recover(path) -> Recording:
    """
    Make the bag at ``path`` complete: indexed MCAP file and ``metadata.yaml``.

    A cut file is rewritten from its readable records and kept beside the new one with the
    suffix ``.cut``. A complete file is left as it is (only a missing ``metadata.yaml`` is
    written). Returns what was read.
    """
    file = mcap_file(path)
    recording = read(file)
    directory = file.parent
    if not recording.complete:
        partial = file.with_name(file.name + '.partial')
        with open(partial, 'wb') as stream:
            write(recording, stream)
            stream.flush()
            os.fsync(stream.fileno())
        os.replace(file, file.with_name(file.name + DAMAGED_SUFFIX))
        os.replace(partial, file)
    if not recording.complete or not (directory / METADATA_FILE).exists():
        write_metadata_file(directory, _metadata_text(recording, file.name))
    return recording


def write(recording: Recording, stream) -> None:
    """Write the records of ``recording`` as one complete MCAP file."""
    writer = Writer(stream, compression=CompressionType.NONE)
    writer.start(profile=recording.profile, library=recording.library)
    schema_ids = {old: writer.register_schema(s.name, s.encoding, s.data)
                  for old, s in recording.schemas.items()}
    channel_ids = {old: writer.register_channel(c.topic, c.message_encoding,
                                                schema_ids.get(c.schema_id, 0), c.metadata)
                   for old, c in recording.channels.items()}
    for message in recording.messages:
        writer.add_message(channel_ids[message.channel_id], log_time=message.log_time,
                           data=message.data, publish_time=message.publish_time,
                           sequence=message.sequence)
    for attachment in recording.attachments:
        writer.add_attachment(attachment.create_time, attachment.log_time, attachment.name,
                              attachment.media_type, attachment.data)
    for metadata in recording.metadata:
        writer.add_metadata(metadata.name, metadata.metadata)
    writer.add_metadata('rosbag2', {'serialized_metadata': _metadata_text(
        recording, Path(recording.path).name)})
    writer.finish()


def _metadata_text(recording: Recording, file_name: str) -> str:
    times = [m.log_time for m in recording.messages]
    return metadata_yaml(file_name, recording.topics(), recording.counts(),
                         min(times, default=0), max(times, default=0))
