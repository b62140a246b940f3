"""
A rosbag2-layout MCAP bag, written one record at a time (SPEC section 6).

The layout is what ``ros2 bag record -s mcap`` writes on Jazzy, so that ``ros2 bag``,
Foxglove and the independent ``rosbags`` library read it: a directory ``<bag>/`` holding
``<bag>_0.mcap`` and, once closed, ``metadata.yaml`` (version 9); an MCAP header with profile
``ros2``; ``ros2msg`` schemas (``msgdefs``); channels with ``cdr`` encoding and the metadata
``offered_qos_profiles`` and ``topic_type_hash``; a metadata record ``rosbag2`` holding the
same YAML as ``metadata.yaml``. Chunks are uncompressed, as rosbag2's default.
"""

from dataclasses import dataclass, field
import os
from pathlib import Path
from typing import Dict, Iterable, Mapping, Optional, Sequence

from mcap.writer import CompressionType, Writer
from wafer_planner_ros import __version__
from wafer_planner_ros.recording import msgdefs
import yaml  # after the package: ament_flake8 takes wafer_planner_ros for a third party

METADATA_FILE = 'metadata.yaml'
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


def bag_file(directory: Path) -> Path:
    """Return the MCAP file of a bag directory (``<dir>/<dir name>_0.mcap``)."""
    return Path(directory) / f'{Path(directory).name}_0.mcap'


def metadata_yaml(file_name: str, topics: Iterable[Topic], counts: Mapping[str, int],
                  start_ns: int, end_ns: int) -> str:
    """Return the text of ``metadata.yaml`` for a one-file bag."""
    total = sum(counts.values())
    if total == 0:
        start_ns = end_ns = 0
    duration = {'nanoseconds': max(end_ns - start_ns, 0)}
    starting = {'nanoseconds_since_epoch': start_ns}
    return _yaml({'rosbag2_bagfile_information': {
        'version': 9,
        'storage_identifier': 'mcap',
        'duration': duration,
        'starting_time': starting,
        'message_count': total,
        'topics_with_message_count': [
            {'topic_metadata': {'name': t.name, 'type': t.type, 'serialization_format': 'cdr',
                                'offered_qos_profiles': [dict(t.qos)],
                                'type_description_hash': t.hash()},
             'message_count': counts.get(t.name, 0)} for t in topics],
        'compression_format': '',
        'compression_mode': '',
        'relative_file_paths': [file_name],
        'files': [{'path': file_name, 'starting_time': starting, 'duration': duration,
                   'message_count': total}],
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


class BagWriter:
    """
    Write one bag: messages, attachments and metadata, flushed on demand, closed cleanly.

    Not thread-safe: ``Recorder`` owns one and calls it from its own thread.
    """

    def __init__(self, directory: Path, topics: Sequence[Topic], opener=open):
        """Create ``directory`` (it must not exist yet) and start its MCAP file."""
        self.topics = tuple(topics)
        # Definitions first: a missing message package leaves no empty directory behind.
        channels = [(t, msgdefs.definition(t.type).encode(), t.channel_metadata())
                    for t in self.topics]
        self.directory = Path(directory)
        self.directory.mkdir(parents=True, exist_ok=False)
        self.path = bag_file(self.directory)
        self.counts = {t.name: 0 for t in self.topics}
        self.start_ns: Optional[int] = None
        self.end_ns = 0
        self._stream = opener(self.path, 'wb')
        try:
            self._stream.fileno()
            self._watched = not network_filesystem(self.directory)
        except (OSError, ValueError, AttributeError):  # no descriptor: not a file on a disk
            self._watched = False
        self._writer = Writer(self._stream, compression=CompressionType.NONE)
        self._writer.start(profile='ros2', library=f'wafer_planner_ros {__version__}')
        self._channels = {}
        for topic, definition, metadata in channels:
            schema = self._writer.register_schema(name=topic.type, encoding='ros2msg',
                                                  data=definition)
            self._channels[topic.name] = self._writer.register_channel(
                topic=topic.name, message_encoding='cdr', schema_id=schema, metadata=metadata)
        self.closed = False

    def write(self, topic: str, data: bytes, log_time: int, publish_time: int,
              sequence: int = 0) -> None:
        """Add one serialised message (times in ns since the epoch)."""
        self._writer.add_message(self._channels[topic], log_time=log_time, data=data,
                                 publish_time=publish_time, sequence=sequence)
        self.counts[topic] += 1
        self.start_ns = log_time if self.start_ns is None else min(self.start_ns, log_time)
        self.end_ns = max(self.end_ns, log_time)

    def attach(self, name: str, data: bytes, log_time: int,
               media_type: str = 'application/yaml') -> None:
        """Add an attachment (a file kept inside the recording)."""
        self._writer.add_attachment(create_time=log_time, log_time=log_time, name=name,
                                    media_type=media_type, data=data)

    def metadata(self, name: str, values: Mapping[str, str]) -> None:
        """Add a metadata record (string keys and values)."""
        self._writer.add_metadata(name, {str(k): str(v) for k, v in values.items()})

    def flush(self) -> None:
        """Hand everything so far to the operating system (a process crash loses none of it)."""
        self._writer.flush()

    def sync(self) -> None:
        """Make what was flushed durable on the disk (``fsync``), against power loss."""
        os.fsync(self._stream.fileno())

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
        """Return ``metadata.yaml`` as it would be written now."""
        return metadata_yaml(self.path.name, self.topics, self.counts,
                             self.start_ns or 0, self.end_ns)

    def close(self) -> Path:
        """Finish the file (summary and index) and write ``metadata.yaml``; return its path."""
        if self.closed:
            return self.directory / METADATA_FILE
        self.closed = True
        text = self.metadata_text()
        try:
            self._writer.add_metadata('rosbag2', {'serialized_metadata': text})
            self._writer.finish()
            self._stream.flush()
            os.fsync(self._stream.fileno())
        finally:
            self._stream.close()
        return write_metadata_file(self.directory, text)

    def abandon(self) -> None:
        """Close the stream without finishing (after a write error); never raise."""
        self.closed = True
        try:
            self._stream.close()
        except OSError:
            pass


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
