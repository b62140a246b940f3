"""
A rosbag2-layout MCAP bag, written one record at a time, split into files.

The layout is what ``ros2 bag record -s mcap`` writes on Jazzy, so that ``ros2 bag``,
Foxglove and the independent ``rosbags`` library read it: a directory ``<bag>/`` holding
``<bag>_0.mcap``, ``<bag>_1.mcap``, ... (one file until ``split``) and, once closed,
``metadata.yaml`` (version 9) listing them; in each file an MCAP header with profile
``ros2``, ``ros2msg`` schemas (``msgdefs``), channels with ``cdr`` encoding and the metadata
``offered_qos_profiles`` and ``topic_type_hash``, and a metadata record ``rosbag2`` holding
the YAML of the bag as it was when the file was finished. Every finished file is a
complete, indexed MCAP file that can be read alone. Chunks are zstd-compressed, as
rosbag2's ``zstd_fast`` storage preset writes them and every MCAP reader reads them: the
roadmap markers shrink to a small part of their size, a trajectory less.
"""

from dataclasses import dataclass, field
import io
import os
from pathlib import Path
import re
from typing import Dict, IO, Iterable, List, Mapping, Optional, Sequence

from mcap.writer import CompressionType, Writer
from wafer_planner_ros import __version__
from wafer_planner_ros.recording import msgdefs
import yaml  # after the package: ament_flake8 takes wafer_planner_ros for a third party

METADATA_FILE = 'metadata.yaml'
CHUNK_SIZE = 1 << 20
"""Bytes after which the MCAP writer ends a chunk by itself (a flush ends one too)."""
ROS_DISTRO = 'jazzy'
MOUNTS = Path('/proc/self/mountinfo')
NETWORK_FILESYSTEMS = frozenset({'nfs', 'nfs4', 'cifs', 'smb3', 'smbfs', 'ceph', 'glusterfs',
                                 'lustre', 'afs', '9p', 'fuse'})
"""Where ``BagWriter.deleted`` does not look (``fuse.*`` counts as ``fuse``)."""
_INFINITE = {'sec': 9223372036, 'nsec': 854775807}  # rmw's "infinite" duration


def qos(reliable: bool = True, keep_all: bool = False, depth: int = 10,
        transient_local: bool = False) -> dict:
    """Return an offered QoS profile as rosbag2 (metadata version 9) writes it."""
    return {'history': 'keep_all' if keep_all else 'keep_last', 'depth': depth,
            'reliability': 'reliable' if reliable else 'best_effort',
            'durability': 'transient_local' if transient_local else 'volatile',
            'deadline': dict(_INFINITE), 'lifespan': dict(_INFINITE),
            'liveliness': 'automatic', 'liveliness_lease_duration': dict(_INFINITE),
            'avoid_ros_namespace_conventions': False}


@dataclass(frozen=True)
class Topic:
    """A recorded topic: its name, message type (``pkg/msg/Type``) and offered QoS."""

    name: str
    type: str  # noqa: A003 - rosbag2's name for it
    qos: Mapping = field(default_factory=qos)
    type_hash: str = ''
    """``RIHS01_...``; empty: looked up from the installed message package."""

    def hash(self) -> str:  # noqa: A003 - the hash of the type, as rosbag2 calls it
        """Return the type's ``RIHS01_`` hash."""
        return self.type_hash or msgdefs.type_hash(self.type)

    def channel_metadata(self) -> Dict[str, str]:
        """Return the MCAP channel metadata rosbag2 writes for this topic."""
        return {'offered_qos_profiles': _yaml([dict(self.qos)]),
                'topic_type_hash': self.hash()}

    @classmethod
    def from_channel(cls, topic: str, type_name: str, metadata: Mapping[str, str]) -> 'Topic':
        """Return the topic an MCAP channel written like rosbag2 describes."""
        profiles = yaml.safe_load(metadata.get('offered_qos_profiles') or '[]') or []
        return cls(topic, type_name, profiles[0] if profiles else qos(),
                   metadata.get('topic_type_hash', ''))


def bag_file(directory: Path, index: int = 0) -> Path:
    """Return file ``index`` of a bag directory (``<dir>/<dir name>_<index>.mcap``)."""
    return Path(directory) / f'{Path(directory).name}_{index}.mcap'


_SPLIT = re.compile(r'_(\d+)\.mcap$')


def split_index(path: Path) -> Optional[int]:
    """Return the split number of ``<name>_<k>.mcap`` (None for another name)."""
    found = _SPLIT.search(Path(path).name)
    return int(found.group(1)) if found else None


def bag_files(directory: Path) -> List[Path]:
    """Return the MCAP files of a bag directory in split order (others after, by name)."""
    files = [p for p in Path(directory).glob('*.mcap') if p.is_file()]
    return sorted(files, key=lambda p: (split_index(p) is None, split_index(p) or 0, p.name))


@dataclass
class FileInfo:
    """One file of a bag as ``metadata.yaml`` lists it: its messages per topic and times."""

    name: str
    counts: Dict[str, int] = field(default_factory=dict)
    start_ns: int = 0
    """Log time of the first message (ns since the epoch; 0 without messages)."""
    end_ns: int = 0

    @property
    def message_count(self) -> int:
        """Return the number of messages in the file."""
        return sum(self.counts.values())

    def add(self, topic: str, log_time: int) -> None:
        """Count one message."""
        self.start_ns = log_time if not self.message_count else min(self.start_ns, log_time)
        self.end_ns = max(self.end_ns, log_time)
        self.counts[topic] = self.counts.get(topic, 0) + 1


def metadata_yaml(topics: Iterable[Topic], files: Sequence[FileInfo]) -> str:
    """Return the text of ``metadata.yaml`` for a bag of ``files`` (in split order)."""
    topics = tuple(topics)
    counted = [f for f in files if f.message_count]
    start_ns = min((f.start_ns for f in counted), default=0)
    end_ns = max((f.end_ns for f in counted), default=0)

    def times(start: int, end: int) -> dict:
        return {'starting_time': {'nanoseconds_since_epoch': start},
                'duration': {'nanoseconds': max(end - start, 0)}}
    overall = times(start_ns, end_ns)
    return _yaml({'rosbag2_bagfile_information': {
        'version': 9,
        'storage_identifier': 'mcap',
        'duration': overall['duration'],
        'starting_time': overall['starting_time'],
        'message_count': sum(f.message_count for f in files),
        'topics_with_message_count': [
            {'topic_metadata': {'name': t.name, 'type': t.type, 'serialization_format': 'cdr',
                                'offered_qos_profiles': [dict(t.qos)],
                                'type_description_hash': t.hash()},
             'message_count': sum(f.counts.get(t.name, 0) for f in files)} for t in topics],
        'compression_format': '',
        'compression_mode': '',
        'relative_file_paths': [f.name for f in files],
        'files': [{'path': f.name, **(times(f.start_ns, f.end_ns) if f.message_count
                                      else times(0, 0)),
                   'message_count': f.message_count} for f in files],
        'custom_data': {'writer': f'wafer_planner_ros {__version__}'},
        'ros_distro': ROS_DISTRO,
    }})


def write_metadata_file(directory: Path, text: str) -> Path:
    """Write ``metadata.yaml`` into ``directory`` atomically; return its path."""
    path = Path(directory) / METADATA_FILE
    partial = path.with_name(METADATA_FILE + '.partial')
    with open(partial, 'w') as stream:
        stream.write(text)
        stream.flush()
        os.fsync(stream.fileno())
    os.replace(partial, path)
    return path


def sync_and_close(stream: IO) -> None:
    """``fsync`` a finished file (when it is one on a disk) and close it."""
    try:
        try:
            descriptor = stream.fileno()
        except (OSError, ValueError, AttributeError, io.UnsupportedOperation):
            return  # not a file on a disk: nothing to sync
        os.fsync(descriptor)
    finally:
        stream.close()


class BagWriter:
    """
    Write one bag: messages, attachments and metadata, flushed on demand, closed cleanly.

    ``finish_file`` and ``next_file`` split the bag; ``projected_size`` says how
    large the current file would be, finished, with some more messages in it (an upper
    bound: the chunk still being filled counts uncompressed). Not thread-safe:
    ``Recorder`` owns one and calls it under its lock.
    """

    def __init__(self, directory: Path, topics: Sequence[Topic], opener=open):
        """Create ``directory`` (it must not exist yet) and start its first MCAP file."""
        self.topics = tuple(topics)
        # Definitions first: a missing message package leaves no empty directory behind.
        self._definitions = [(t, msgdefs.definition(t.type).encode(), t.channel_metadata())
                             for t in self.topics]
        self.directory = Path(directory)
        self.directory.mkdir(parents=True, exist_ok=False)
        self._opener = opener
        self.files: List[FileInfo] = []
        """Every file of the bag so far, the current one last."""
        self.closed = False
        self._open(0)

    def _open(self, index: int) -> None:
        self.path = bag_file(self.directory, index)
        self._stream = self._opener(self.path, 'wb')
        try:
            self._stream.fileno()
            self._watched = not network_filesystem(self.directory)
        except (OSError, ValueError, AttributeError):  # no descriptor: not a file on a disk
            self._watched = False
        self._writer = Writer(self._stream, chunk_size=CHUNK_SIZE,
                              compression=CompressionType.ZSTD)
        self._writer.start(profile='ros2', library=f'wafer_planner_ros {__version__}')
        self._channels = {}
        for topic, definition, metadata in self._definitions:
            schema = self._writer.register_schema(name=topic.type, encoding='ros2msg',
                                                  data=definition)
            self._channels[topic.name] = self._writer.register_channel(
                topic=topic.name, message_encoding='cdr', schema_id=schema, metadata=metadata)
        self.file = FileInfo(self.path.name, {t.name: 0 for t in self.topics})
        self.files.append(self.file)
        self._size = _SizeBound(self._definitions, self.topics, self.files)

    def write(self, topic: str, data: bytes, log_time: int, publish_time: int,
              sequence: int = 0) -> None:
        """Add one serialised message (times in ns since the epoch)."""
        self._writer.add_message(self._channels[topic], log_time=log_time, data=data,
                                 publish_time=publish_time, sequence=sequence)
        self.file.add(topic, log_time)
        self._size.message(len(data))

    def attach(self, name: str, data: bytes, log_time: int,
               media_type: str = 'application/yaml') -> None:
        """Add an attachment (a file kept inside the recording)."""
        self._writer.add_attachment(create_time=log_time, log_time=log_time, name=name,
                                    media_type=media_type, data=data)
        self._size.attachment(name, media_type)

    def metadata(self, name: str, values: Mapping[str, str]) -> None:
        """Add a metadata record (string keys and values)."""
        self._writer.add_metadata(name, {str(k): str(v) for k, v in values.items()})
        self._size.metadata(name)

    def flush(self) -> None:
        """Hand everything so far to the operating system (a process crash loses none of it)."""
        self._writer.flush()
        self._size.flushed()

    def sync(self) -> None:
        """Make what was flushed durable on the disk (``fsync``), against power loss."""
        os.fsync(self._stream.fileno())

    def projected_size(self, sizes: Iterable[int] = ()) -> int:
        """Return an upper bound of the finished file's size with messages of ``sizes`` more."""
        return self._size.bound(self._stream.tell(), sizes)

    def deleted(self) -> bool:
        """
        Return True once the open file is deleted, alone or with its directory.

        Linux lets a deleted file be written on, to no avail, until it is closed. One
        ``fstat``, about a microsecond; not on a network filesystem, where it waits for the
        server and where a deleted open file lives on under another name anyway.
        """
        if self.closed or not self._watched:
            return False
        try:
            return os.fstat(self._stream.fileno()).st_nlink == 0
        except (OSError, ValueError):  # closed meanwhile: a write will tell what went wrong
            return False

    def metadata_text(self) -> str:
        """Return ``metadata.yaml`` as it would be written now (the files still there)."""
        return metadata_yaml(self.topics, [f for f in self.files if f is self.file
                                           or (self.directory / f.name).exists()])

    def finish_file(self) -> IO:
        """
        Finish the current file (summary, index, footer); ``next_file`` starts the next.

        The finished file is handed to the operating system, not synced: return its
        stream, still open, for ``sync_and_close``.
        """
        self._finish()
        return self._stream

    def next_file(self) -> None:
        """Start the bag's next file, after ``finish_file``."""
        self._open(split_index(self.path) + 1)

    def close(self) -> Path:
        """Finish the file (summary and index) and write ``metadata.yaml``; return its path."""
        if self.closed:
            return self.directory / METADATA_FILE
        self.closed = True
        try:
            self._finish()
        finally:
            sync_and_close(self._stream)
        return write_metadata_file(self.directory, self.metadata_text())

    def _finish(self) -> None:
        self._writer.add_metadata('rosbag2', {'serialized_metadata': self.metadata_text()})
        self._writer.finish()
        self._stream.flush()

    def abandon(self) -> None:
        """Close the stream without finishing (after a write error); never raise."""
        self.closed = True
        try:
            self._stream.close()
        except OSError:
            pass


class _SizeBound:
    """
    An upper bound of the size an MCAP file being written will have once finished.

    What is in the stream, plus the chunk being filled counted uncompressed, plus what
    ``Writer.finish`` adds: the data end record, the summary (schemas, channels,
    statistics, one index per chunk, attachment and metadata record) and its offsets, the
    ``rosbag2`` metadata record, the footer and the closing magic. Record sizes as the MCAP
    specification gives them (opcode 1 byte, length 8, strings and maps prefixed by 4).
    """

    CHUNK = 1 + 8 + 8 + 8 + 8 + 4 + 4 + len('zstd') + 8
    """A chunk record without its records."""
    MESSAGE = 1 + 8 + 2 + 4 + 8 + 8 + 16
    """A message record without its data, and its entry in a message index."""
    MESSAGE_INDEX = 1 + 8 + 2 + 4
    CHUNK_INDEX = 1 + 8 + 8 + 8 + 8 + 8 + 4 + 8 + 4 + len('zstd') + 8 + 8
    """Without its message index offsets (10 bytes per channel)."""
    TAIL = (1 + 8 + 4) + 6 * (1 + 8 + 1 + 8 + 8) + (1 + 8 + 8 + 8 + 4) + 8
    """Data end, six summary offsets, footer, magic."""
    MARGIN = 64

    def __init__(self, definitions, topics, files):
        channels = len(definitions)
        schemas = sum(1 + 8 + 2 + 4 + len(t.type) + 4 + len('ros2msg') + 4 + len(d)
                      for t, d, _ in definitions)
        channel_records = sum(
            1 + 8 + 2 + 2 + 4 + len(t.name) + 4 + len('cdr') + 4
            + sum(8 + len(k.encode()) + len(v.encode()) for k, v in m.items())
            for t, _, m in definitions)
        statistics = 1 + 8 + 8 + 2 + 4 + 4 + 4 + 4 + 8 + 8 + 4 + 10 * channels
        # The bag's YAML at its longest: one more file, every number at 19 digits.
        longest = [FileInfo(f.name + '_', {t.name: 10 ** 18 for t in topics}, 10 ** 18,
                            9 * 10 ** 18) for f in files + files[-1:]]
        text = len(metadata_yaml(topics, longest).encode())
        rosbag2 = (1 + 8 + 4 + len('rosbag2') + 4 + 8 + len('serialized_metadata') + text
                   + 1 + 8 + 8 + 8 + 4 + len('rosbag2'))
        self._chunk_index = self.CHUNK_INDEX + 10 * channels
        self._fixed = (schemas + channel_records + statistics + rosbag2 + self.TAIL
                       + self.MARGIN)
        self._pending = schemas + channel_records  # the first chunk holds them too
        self._messages = 0
        self._indexes = 0
        self._channels = channels

    def message(self, size: int) -> None:
        self._pending += self.MESSAGE + size
        self._messages += 1

    def attachment(self, name: str, media_type: str) -> None:
        self._indexes += 1 + 8 + 8 + 8 + 8 + 8 + 8 + 4 + len(name.encode()) + 4 + len(
            media_type.encode())

    def metadata(self, name: str) -> None:
        self._indexes += 1 + 8 + 8 + 8 + 4 + len(name.encode())

    def flushed(self) -> None:
        if self._messages:  # a chunk without messages is not written: it stays pending
            self._indexes += self._chunk_index
            self._pending, self._messages = 0, 0

    def bound(self, written: int, sizes: Iterable[int]) -> int:
        sizes = list(sizes)
        pending = self._pending + sum(self.MESSAGE + s for s in sizes)
        chunks = 1 + pending // CHUNK_SIZE  # the Writer also ends a chunk past CHUNK_SIZE
        return (written + pending + chunks * (self.CHUNK + self._chunk_index)
                + self._channels * self.MESSAGE_INDEX * chunks + self._indexes + self._fixed)


def network_filesystem(directory: Path, mounts: Path = MOUNTS) -> bool:
    """Return True when ``directory`` is on a network (or FUSE) filesystem, as far as known."""
    try:
        device = os.stat(directory).st_dev
        lines = Path(mounts).read_text().splitlines()
    except OSError:
        return False
    wanted = f'{os.major(device)}:{os.minor(device)}'
    for line in lines:
        # mount id, parent id, major:minor, root, mount point, options, [optional], -, type
        fields = line.split()
        if len(fields) > 7 and fields[2] == wanted and '-' in fields[6:-1]:
            kind = fields[fields.index('-', 6) + 1]
            return kind.split('.')[0] in NETWORK_FILESYSTEMS
    return False


class _Dumper(yaml.SafeDumper):
    """``yaml.SafeDumper`` writing a mapping shared by two places out twice."""

    def ignore_aliases(self, data) -> bool:
        # Never anchors and aliases (``&id001``, ``*id001``): rosbag2 writes none. Topics
        # sharing a profile share its nested durations; here, not at every copy, because a
        # single shallow copy anywhere would bring the aliases back.
        return True


def _yaml(value) -> str:
    return yaml.dump(value, Dumper=_Dumper, sort_keys=False, default_flow_style=False,
                     width=1000)
