"""
Reading a recording record by record: one file, or every file of a split bag as one.

A bag whose writer was killed has no summary, index or footer in its last file, and no
``metadata.yaml``: seeking readers (``rosbags``, ``ros2 bag``) refuse it. Read linearly,
such a file yields every record up to the last one written whole (``recover`` makes it
complete). A bag directory is read file after file in split order, whichever of its files
are left (retention removes the oldest ones): each file begins with what the node records
for every file (schemas, cell file, roadmap load, parameters, markers), so the copies are
read once, and a query is in one file only, so nothing else is repeated.
"""

from dataclasses import dataclass, field
from pathlib import Path
import struct
from typing import Dict, List, Tuple

from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Attachment, Channel, Footer, Header, Message, Metadata, Schema
from mcap.stream_reader import StreamReader

from wafer_planner_ros.errors import WaferPlannerError
from wafer_planner_ros.recording.bag import bag_files, FileInfo, metadata_yaml, Topic


class RecordingError(WaferPlannerError):
    """A recording that cannot be read at all; names the file and the reason."""


@dataclass
class Recording:
    """Every record of one MCAP file, or of the files of a bag one after the other."""

    path: Path
    """The file, or the bag directory."""
    profile: str = ''
    library: str = ''
    schemas: Dict[int, Schema] = field(default_factory=dict)
    channels: Dict[int, Channel] = field(default_factory=dict)
    messages: List[Message] = field(default_factory=list)
    attachments: List[Attachment] = field(default_factory=list)
    metadata: List[Metadata] = field(default_factory=list)
    complete: bool = False
    """True when every file ends with its footer (was closed cleanly)."""
    cut: str = ''
    """Why reading stopped before a footer (empty when complete); names the file in a bag."""
    files: List[Path] = field(default_factory=list)
    """The MCAP files read, in order."""
    cut_files: List[Path] = field(default_factory=list)
    """Those of them that end before their footer."""

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

    def info(self) -> FileInfo:
        """Return what ``metadata.yaml`` lists of a file holding these messages."""
        times = [m.log_time for m in self.messages]
        return FileInfo(Path(self.path).name, self.counts(), min(times, default=0),
                        max(times, default=0))


def recording_files(path) -> List[Path]:
    """Return the MCAP files of a bag directory in split order (``[path]`` for a file)."""
    path = Path(path)
    if path.is_file():
        return [path]
    if not path.is_dir():
        raise RecordingError(f'{path}: no such recording (a bag directory or .mcap file)')
    found = bag_files(path)
    if not found:
        raise RecordingError(f'{path}: no .mcap file in it')
    return found


def read(path) -> Recording:
    """
    Read every record of a recording, stopping quietly where a crash cut a file off.

    A bag directory of several files is read as one recording; a file that cannot be read
    at all is named in ``cut`` and left out (a ``RecordingError`` when none can be read).
    """
    files = recording_files(path)
    if len(files) == 1:
        recording = read_file(files[0])
        recording.path = Path(path)
        return recording
    parts, unreadable = [], []
    for file in files:
        try:
            parts.append(read_file(file))
        except RecordingError as exc:
            unreadable.append(str(exc))
    if not parts:
        raise RecordingError('; '.join(unreadable))
    merged = merge(Path(path), parts)
    if unreadable:
        merged.complete = False
        merged.cut = '; '.join(filter(None, [merged.cut, *unreadable]))
    return merged


def read_file(file: Path) -> Recording:
    """Read every record of one MCAP file, stopping quietly where a crash cut it off."""
    file = Path(file)
    recording = Recording(file, files=[file])
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
    if not recording.complete:
        recording.cut_files = [file]
    return recording


def merge(path: Path, parts: List[Recording]) -> Recording:
    """Return the files read in ``parts`` (in order) as one recording of the bag ``path``."""
    merged = Recording(path, profile=parts[0].profile, library=parts[0].library,
                       complete=all(p.complete for p in parts))
    merged.cut = '; '.join(f'{p.path.name}: {p.cut}' for p in parts if p.cut)
    schema_ids: Dict[Tuple, int] = {}
    channel_ids: Dict[Tuple, int] = {}
    seen_attachments, seen_metadata = set(), set()
    for part in parts:
        merged.files += part.files
        merged.cut_files += part.cut_files
        new_schema = {}
        for old, schema in part.schemas.items():
            key = (schema.name, schema.encoding, schema.data)
            if key not in schema_ids:
                schema_ids[key] = len(schema_ids) + 1
                merged.schemas[schema_ids[key]] = Schema(
                    id=schema_ids[key], data=schema.data, encoding=schema.encoding,
                    name=schema.name)
            new_schema[old] = schema_ids[key]
        new_channel = {}
        for old, channel in part.channels.items():
            schema = new_schema.get(channel.schema_id, 0)
            key = (channel.topic, channel.message_encoding, schema)
            if key not in channel_ids:
                channel_ids[key] = len(channel_ids) + 1
                merged.channels[channel_ids[key]] = Channel(
                    id=channel_ids[key], topic=channel.topic,
                    message_encoding=channel.message_encoding, metadata=channel.metadata,
                    schema_id=schema)
            new_channel[old] = channel_ids[key]
        merged.messages += [Message(channel_id=new_channel[m.channel_id], log_time=m.log_time,
                                    data=m.data, publish_time=m.publish_time,
                                    sequence=m.sequence) for m in part.messages]
        for attachment in part.attachments:  # every file's copy of the cell, parameters
            key = (attachment.name, attachment.log_time, attachment.data)
            if key not in seen_attachments:
                seen_attachments.add(key)
                merged.attachments.append(attachment)
        for record in part.metadata:  # and roadmap loads
            key = (record.name, tuple(sorted(record.metadata.items())))
            if key not in seen_metadata:
                seen_metadata.add(key)
                merged.metadata.append(record)
    return merged


def file_info(file: Path) -> Tuple[FileInfo, List[Topic]]:
    """Return what ``metadata.yaml`` lists of one MCAP file, and its topics."""
    file = Path(file)
    try:
        with open(file, 'rb') as stream:
            summary = make_reader(stream).get_summary()
    except (McapError, struct.error, ValueError, EOFError, OSError):
        summary = None
    if summary is not None and summary.statistics is not None:
        statistics = summary.statistics
        counts = {c.topic: statistics.channel_message_counts.get(i, 0)
                  for i, c in summary.channels.items()}
        topics = [Topic.from_channel(c.topic, summary.schemas[c.schema_id].name, c.metadata)
                  for c in summary.channels.values() if c.schema_id in summary.schemas]
        return FileInfo(file.name, counts, statistics.message_start_time,
                        statistics.message_end_time), topics
    recording = read_file(file)  # cut off: read through
    return recording.info(), recording.topics()


def describe(bag: Path) -> str:
    """Return ``metadata.yaml`` for the MCAP files a bag directory holds now."""
    infos, topics = [], {}
    for file in recording_files(bag):
        info, found = file_info(file)
        infos.append(info)
        for topic in found:
            topics.setdefault(topic.name, topic)
    return metadata_yaml(topics.values(), infos)


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
