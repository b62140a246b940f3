"""
The recording core: layout, definitions, failures, cut files and recovery.

The recorder itself is ROS-free; these tests use rclpy's serialiser and message classes only
to make real CDR bytes to record, and ``rosbags`` to read them back independently.
"""

import base64
import errno
import io
import os
import shutil
import threading
import time

from mcap.reader import make_reader
import numpy as np
import pytest
from rclpy.serialization import serialize_message
from rosbags.rosbag2 import Reader
from rosbags.typesys import get_typestore, Stores
from rosbags.typesys.msg import get_types_from_msg
from std_msgs.msg import String

from wafer_planner_ros.node.recording import NodeRecording
from wafer_planner_ros.recording import msgdefs
from wafer_planner_ros.recording.bag import bag_file, network_filesystem, qos, Topic
from wafer_planner_ros.recording.reading import read, RecordingError
from wafer_planner_ros.recording.recorder import Recorder
from wafer_planner_ros.recording.recover import recover
from wafer_planner_ros.service.cdr import joint_trajectory
import yaml

TYPES = ('std_msgs/msg/String', 'trajectory_msgs/msg/JointTrajectory',
         'diagnostic_msgs/msg/DiagnosticStatus', 'visualization_msgs/msg/MarkerArray')
TOPICS = (Topic('/wafer_planner/plan_station_request', 'std_msgs/msg/String',
                qos(keep_all=True, depth=1000)),
          Topic('/wafer_planner/trajectory', 'trajectory_msgs/msg/JointTrajectory'))


@pytest.mark.parametrize('type_name', TYPES)
def test_definitions_are_what_an_independent_parser_rebuilds(type_name):
    """Our schema text parses (rosbags) into the same types the Jazzy type store has."""
    store = get_typestore(Stores.ROS2_JAZZY)
    text = msgdefs.definition(type_name)
    parsed = get_types_from_msg(text, type_name)
    assert type_name in parsed
    for name, fields in parsed.items():
        assert fields == store.fielddefs[name], name
    package = type_name.split('/')[0]
    for dependency in msgdefs.dependencies(package, text.split('=' * 80)[0]):
        assert f'MSG: {dependency}\n' in text
    assert text.count('MSG: ') == len(set(text.split('MSG: ')[1:]))  # each once
    # The hash is the one rosbags computes from the type store.
    assert msgdefs.type_hash(type_name) == store.hash_rihs01(type_name)


def _session(directory, count: int) -> Recorder:
    """Record ``count`` queries as the node does: a request, then its answer, flushed."""
    recorder = Recorder(directory, TOPICS)
    rng = np.random.default_rng(count)
    for k in range(1, count + 1):
        request = serialize_message(String(data=f'{{"id": "r{k}"}}'))
        assert recorder.write_now([(TOPICS[0].name, request, 10 ** 9 * k, 10 ** 9 * k, k)],
                                  flush=False)
        rows = [rng.normal(size=(30, 3)) for _ in range(3)]
        answer = joint_trajectory(k, 0, f'r{k}', ['a', 'b', 'c'], np.arange(30) * 0.01, *rows)
        assert recorder.write_now([(TOPICS[1].name, answer, 10 ** 9 * k + 5,
                                    10 ** 9 * k + 5, k)])
    return recorder


def test_a_closed_bag_is_read_by_rosbags(tmp_path):
    recorder = _session(tmp_path / 'bag', 20)
    assert recorder.close() == tmp_path / 'bag' / 'metadata.yaml'
    store = get_typestore(Stores.ROS2_JAZZY)
    with Reader(tmp_path / 'bag') as reader:
        assert reader.message_count == 40
        assert {c.topic: c.msgcount for c in reader.connections} == {t.name: 20 for t in TOPICS}
        assert reader.duration == 19_000_000_006  # rosbag2: last - first + 1
        frames = [store.deserialize_cdr(raw, c.msgtype).header.frame_id
                  for c, _, raw in reader.messages() if c.topic == TOPICS[1].name]
    assert frames == [f'r{k}' for k in range(1, 21)]
    recording = read(tmp_path / 'bag')
    assert recording.complete and recording.profile == 'ros2'
    assert [m.sequence for m in recording.messages[::2]] == list(range(1, 21))


def test_a_bag_directory_that_exists_is_not_overwritten(tmp_path):
    (tmp_path / 'bag').mkdir()
    with pytest.raises(FileExistsError):
        Recorder(tmp_path / 'bag', TOPICS)


@pytest.mark.parametrize('fraction', [0.3, 0.55, 0.8, 0.97])
def test_a_file_cut_anywhere_recovers_every_message_before_the_cut(tmp_path, fraction):
    recorder = _session(tmp_path / 'bag', 12)
    recorder.close()
    file = bag_file(tmp_path / 'bag')
    whole = file.read_bytes()
    (tmp_path / 'bag' / 'metadata.yaml').unlink()
    file.write_bytes(whole[:int(len(whole) * fraction)])
    with pytest.raises(Exception):  # noqa: B017 - rosbags refuses it, whatever the error
        with Reader(tmp_path / 'bag'):
            pass
    cut = read(tmp_path / 'bag')
    assert not cut.complete and cut.cut
    recovered = recover(tmp_path / 'bag')
    assert (tmp_path / 'bag' / (file.name + '.cut')).read_bytes() == \
        whole[:int(len(whole) * fraction)]
    # One query per flushed chunk: everything before the cut's chunk is back, in order.
    sequences = [m.sequence for m in recovered.messages]
    assert sequences == sorted(sequences) and len(sequences) >= 2 * int(12 * fraction) - 4
    with Reader(tmp_path / 'bag') as reader:
        assert reader.message_count == len(recovered.messages)
        assert len(list(reader.messages())) == len(recovered.messages)
    assert read(tmp_path / 'bag').complete
    again = recover(tmp_path / 'bag')  # a complete bag is left alone
    assert again.complete and len(again.messages) == len(recovered.messages)


def test_a_file_that_is_not_mcap_is_named(tmp_path):
    (tmp_path / 'bag').mkdir()
    (tmp_path / 'bag' / 'bag_0.mcap').write_bytes(b'not an mcap file at all')
    with pytest.raises(RecordingError, match='bag_0.mcap'):
        read(tmp_path / 'bag')
    with pytest.raises(RecordingError, match='no such recording'):
        read(tmp_path / 'missing')


class _FillingDisk(io.BytesIO):
    """A file on a disk that is full after ``room`` bytes; mirrors what it holds to ``path``."""

    def __init__(self, path, room: int):
        super().__init__()
        self.path, self.room = path, room

    def write(self, data) -> int:
        if self.tell() + len(data) > self.room:
            raise OSError(errno.ENOSPC, 'No space left on device')
        written = super().write(data)
        self.path.write_bytes(self.getvalue())
        return written

    def fileno(self) -> int:
        raise io.UnsupportedOperation('no descriptor')


def test_a_full_disk_stops_the_recording_and_says_so(tmp_path):
    errors = []

    def opener(path, mode):
        return _FillingDisk(path, room=12000)
    recorder = Recorder(tmp_path / 'bag', TOPICS, errors.append, opener)
    recorder._writer.sync = lambda: None  # an in-memory file has nothing to fsync
    rng = np.random.default_rng(7)  # chunks are compressed: text that does not compress

    def text() -> str:
        return base64.b64encode(rng.bytes(375)).decode()
    safe = [recorder.write_now([(TOPICS[0].name, serialize_message(String(data=text())),
                                 k, k, k)]) for k in range(1, 30)]
    # Answered at once either way: True while the disk had room, then False.
    first_failure = safe.index(False)
    assert first_failure >= 10 and not any(safe[first_failure:])
    assert recorder.close() is None
    assert len(errors) == 1 and 'No space left on device' in errors[0]
    assert 'No space left on device' in recorder.status()['error']
    assert recorder.status()['dropped'] > 0
    assert recorder.status()['lost'] == len(safe) - first_failure  # each answer not in it
    recorder.record(TOPICS[0].name, b'late', 99, 99, 99)  # ignored, no exception
    # What reached the disk before it filled is recoverable.
    recovered = recover(tmp_path / 'bag')
    assert [m.sequence for m in recovered.messages] == list(range(1, first_failure + 1))


def test_a_stalled_disk_does_not_hold_answers_and_loses_nothing(tmp_path):
    recorder = Recorder(tmp_path / 'bag', TOPICS)
    hung = threading.Event()
    release = threading.Event()

    def hanging_sync() -> None:  # fsync stuck, as on a dead mount
        hung.set()
        release.wait(30)
    recorder._writer.sync = hanging_sync

    def message(k: int):
        return (TOPICS[0].name, serialize_message(String(data=f'm{k}')), k, k, k)
    assert recorder.write_now([message(1)])
    assert hung.wait(10)
    wait_until(recorder.stalled)
    # Queued, not written in place, and the caller is told so at once.
    assert [recorder.write_now([message(k)]) for k in range(2, 6)] == [False] * 4
    assert recorder.status()['stalled'] and recorder.status()['pending'] >= 4
    release.set()
    wait_until(lambda: not recorder.stalled() and recorder.status()['pending'] == 0)
    assert recorder.write_now([message(6)])
    assert recorder.close() is not None
    assert [m.sequence for m in read(tmp_path / 'bag').messages] == [1, 2, 3, 4, 5, 6]


def wait_until(predicate, timeout: float = 10.0) -> None:
    """Wait until ``predicate()`` holds; fail after ``timeout`` s."""
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, 'timed out'
        time.sleep(0.01)


# rosbag2 Jazzy's metadata.yaml, version 9, key by key in its order: the encoders of
# BagMetadata, TopicInformation, TopicMetadata, FileInformation and rclcpp::QoS in
# rosbag2_storage (yaml.hpp, qos.cpp on the jazzy branch). None: a scalar.
DURATION = {'nanoseconds': None}
STARTING_TIME = {'nanoseconds_since_epoch': None}
RMW_TIME = {'sec': None, 'nsec': None}
QOS_PROFILE = {'history': None, 'depth': None, 'reliability': None, 'durability': None,
               'deadline': RMW_TIME, 'lifespan': RMW_TIME, 'liveliness': None,
               'liveliness_lease_duration': RMW_TIME, 'avoid_ros_namespace_conventions': None}
JAZZY_METADATA = {'rosbag2_bagfile_information': {
    'version': None, 'storage_identifier': None, 'duration': DURATION,
    'starting_time': STARTING_TIME, 'message_count': None,
    'topics_with_message_count': [{
        'topic_metadata': {'name': None, 'type': None, 'serialization_format': None,
                           'offered_qos_profiles': [QOS_PROFILE],  # a list from version 9
                           'type_description_hash': None},
        'message_count': None}],
    'compression_format': None, 'compression_mode': None, 'relative_file_paths': [None],
    'files': [{'path': None, 'starting_time': STARTING_TIME, 'duration': DURATION,
               'message_count': None}],
    'custom_data': {'writer': None}, 'ros_distro': None}}


def _layout(value):
    """Return the keys of ``value``, nested and in order; of a list, its items' layouts once."""
    if isinstance(value, dict):
        return tuple((key, _layout(item)) for key, item in value.items())
    if isinstance(value, list):
        layouts = []
        for item in value:
            if _layout(item) not in layouts:
                layouts.append(_layout(item))
        return layouts
    return None


def test_metadata_yaml_is_rosbag2_jazzy_version_9_without_anchors(tmp_path):
    """Topics sharing a profile, as the node's do: no ``&id001`` in the file, rosbag2's keys."""
    shared = qos(keep_all=True, depth=1000)
    topics = (Topic('/wafer_planner/plan_station_request', 'std_msgs/msg/String', shared),
              Topic('/wafer_planner/result', 'diagnostic_msgs/msg/DiagnosticStatus', shared),
              Topic('/wafer_planner/roadmap_markers', 'visualization_msgs/msg/MarkerArray',
                    qos(depth=1, transient_local=True)))
    recorder = Recorder(tmp_path / 'bag', topics)
    request = serialize_message(String(data='{"id": "m1"}'))
    assert recorder.write_now([(topics[0].name, request, 2_000, 2_000, 1)], flush=False)
    assert recorder.write_now([(topics[0].name, request, 7_000, 7_000, 2)])
    path = recorder.close()
    text = path.read_text()
    aliased = [event for event in yaml.parse(text)
               if isinstance(event, yaml.AliasEvent) or getattr(event, 'anchor', None)]
    assert not aliased, text
    assert '&id' not in text and '*id' not in text
    document = yaml.safe_load(text)
    assert _layout(document) == _layout(JAZZY_METADATA)
    info = document['rosbag2_bagfile_information']
    file_name = bag_file(tmp_path / 'bag').name
    assert (info['version'], info['storage_identifier'], info['ros_distro']) == \
        (9, 'mcap', 'jazzy')
    assert info['relative_file_paths'] == [file_name] == [f['path'] for f in info['files']]
    assert info['message_count'] == info['files'][0]['message_count'] == 2
    assert info['duration'] == info['files'][0]['duration'] == {'nanoseconds': 5_000}
    assert info['starting_time'] == {'nanoseconds_since_epoch': 2_000}
    assert [t['message_count'] for t in info['topics_with_message_count']] == [2, 0, 0]
    (profile,) = info['topics_with_message_count'][0]['topic_metadata']['offered_qos_profiles']
    assert profile == {'history': 'keep_all', 'depth': 1000, 'reliability': 'reliable',
                       'durability': 'volatile',
                       'deadline': {'sec': 9223372036, 'nsec': 854775807},
                       'lifespan': {'sec': 9223372036, 'nsec': 854775807},
                       'liveliness': 'automatic',
                       'liveliness_lease_duration': {'sec': 9223372036, 'nsec': 854775807},
                       'avoid_ros_namespace_conventions': False}
    # The same YAML inside the MCAP file, as rosbag2's MCAP plugin keeps it.
    with open(bag_file(tmp_path / 'bag'), 'rb') as stream:
        (inside,) = [m.metadata for m in make_reader(stream).iter_metadata()
                     if m.name == 'rosbag2']
    assert inside == {'serialized_metadata': text}
    # The independent reader takes the profiles as rosbag2 meant them (no UNKNOWN policy).
    with Reader(tmp_path / 'bag') as reader:
        assert reader.ros_distro == 'jazzy' and reader.message_count == 2
        profiles = {c.topic: c.ext.offered_qos_profiles for c in reader.connections}
    (request,) = profiles[topics[0].name]
    assert (request.history.name, request.depth, request.reliability.name,
            request.durability.name, request.liveliness.name) == \
        ('KEEP_ALL', 1000, 'RELIABLE', 'VOLATILE', 'AUTOMATIC')
    (markers,) = profiles[topics[2].name]
    assert (markers.history.name, markers.depth, markers.durability.name) == \
        ('KEEP_LAST', 1, 'TRANSIENT_LOCAL')


def _answer(k: int):
    """Return the messages of answer ``k`` (a trajectory), as ``write_now`` takes them."""
    rows = [np.zeros((4, 3)) for _ in range(3)]
    data = joint_trajectory(k, 0, f'r{k}', ['a', 'b', 'c'], np.arange(4) * 0.01, *rows)
    return [(TOPICS[1].name, data, 10 ** 9 * k, 10 ** 9 * k, k)]


@pytest.mark.parametrize('removed', ['bag', 'parent'])
@pytest.mark.parametrize('next_write', ['answer', 'request'])
def test_a_deleted_directory_stops_the_recording_at_the_next_write(tmp_path, removed,
                                                                   next_write):
    """``rm -rf`` of the bag (or its parent) is reported by the next write, none unsaid."""
    errors = []
    directory = tmp_path / 'recordings' / 'wafer_planner_2026_01_01-00_00_00_000000'
    recorder = Recorder(directory, TOPICS, errors.append)
    assert all(recorder.write_now(_answer(k)) for k in (1, 2))
    shutil.rmtree(directory if removed == 'bag' else directory.parent)
    if next_write == 'answer':
        assert recorder.write_now(_answer(3)) is False  # not claimed to be recorded
    else:
        request = serialize_message(String(data='{"id": "r3"}'))
        assert recorder.write_now([(TOPICS[0].name, request, 3, 3, 3)], flush=False) is False
    message = f'recording stopped: {directory} was deleted'
    assert errors == [message]
    state = recorder.status()
    assert state['error'] == message and state['written'] == 2
    assert (state['dropped'], state['lost']) == (1, int(next_write == 'answer'))
    assert recorder.write_now(_answer(4)) is False  # every later answer is counted
    assert (recorder.status()['dropped'], recorder.status()['lost']) == \
        (2, 1 + int(next_write == 'answer'))
    assert recorder.close() is None and not directory.exists()  # not made again
    assert errors == [message]


def test_status_notices_a_deleted_directory_before_any_write(tmp_path):
    """``/diagnostics`` asks for the status every second: the loss shows while idle too."""
    errors = []
    recorder = Recorder(tmp_path / 'bag', TOPICS, errors.append)
    assert recorder.write_now(_answer(1))
    assert recorder.status()['error'] == ''
    shutil.rmtree(tmp_path / 'bag')
    # A status asked while the recorder's own thread holds the file (``check`` never waits
    # for it) sees the loss at the next one, as ``/diagnostics`` asks every second.
    wait_until(lambda: recorder.status()['error'] != '')
    state = recorder.status()
    assert state['error'] == f'recording stopped: {tmp_path / "bag"} was deleted'
    assert errors == [state['error']] and (state['lost'], state['dropped']) == (0, 0)
    assert recorder.write_now(_answer(2)) is False and recorder.status()['lost'] == 1


def test_answers_queued_on_a_stalled_disk_count_as_lost_when_the_file_is_deleted(tmp_path):
    recorder = Recorder(tmp_path / 'bag', TOPICS)
    hung, release = threading.Event(), threading.Event()

    def hanging_sync() -> None:
        hung.set()
        release.wait(30)
    recorder._writer.sync = hanging_sync
    assert recorder.write_now(_answer(1))
    assert hung.wait(10)
    wait_until(recorder.stalled)
    assert [recorder.write_now(_answer(k)) for k in range(2, 6)] == [False] * 4
    shutil.rmtree(tmp_path / 'bag')
    release.set()  # the thread writes the four, then finds the file gone
    wait_until(lambda: recorder.status()['error'] != '')
    state = recorder.status()
    assert 'was deleted' in state['error']
    assert (state['written'], state['dropped'], state['lost'], state['pending']) == \
        (1, 4, 4, 0)


def test_the_node_says_how_many_answers_a_failed_recording_has_not_recorded(tmp_path):
    """Deleted or full, ``recording_error`` names the directory, what happened, the count."""
    errors = []
    recording = NodeRecording('wafer_planner', TOPICS, TOPICS[1].name, errors.append)
    directory = recording.start(tmp_path)
    data = _answer(1)[0][1]
    assert recording.answer(1, [(TOPICS[1].name, data)]) is True
    shutil.rmtree(directory)
    # Not recorded at all (lost, counted below), rather than recorded late.
    assert recording.answer(2, [(TOPICS[1].name, data)]) is None
    status = recording.status()
    assert not status['recording'] and status['recording_lost'] == 1
    assert status['recording_error'] == \
        f'recording stopped: {directory} was deleted; 1 answer not recorded'
    assert errors == [f'recording stopped: {directory} was deleted']
    assert recording.answer(3, [(TOPICS[1].name, data)]) is None
    assert recording.status()['recording_error'].endswith('; 2 answers not recorded')
    assert recording.stop() == (directory, f'recording stopped: {directory} was deleted; '
                                           '2 answers not recorded')
    assert recording.status()['recording_error'].endswith('; 2 answers not recorded')
    # A full disk is accounted for the same way.
    recording = NodeRecording('wafer_planner', TOPICS, TOPICS[1].name, errors.append)
    directory = recording.start(tmp_path)

    def full() -> None:
        raise OSError(errno.ENOSPC, 'No space left on device')
    recording._recorder._writer.flush = full
    assert [recording.answer(k, [(TOPICS[1].name, data)]) for k in (1, 2, 3)] == [None] * 3
    status = recording.status()
    assert status['recording_lost'] == 3 and str(directory) in status['recording_error']
    assert status['recording_error'].endswith('No space left on device; 3 answers not recorded')


@pytest.mark.parametrize('kind, network', [('ext4', False), ('tmpfs', False), ('nfs4', True),
                                           ('cifs', True), ('fuse.sshfs', True)])
def test_no_deletion_check_on_network_filesystems(tmp_path, kind, network):
    """There ``fstat`` waits for the server, and a deleted open file lives on renamed."""
    device = tmp_path.stat().st_dev
    mounts = tmp_path / 'mountinfo'
    mounts.write_text(
        '22 27 0:21 / /proc rw,relatime - proc proc rw\n'
        f'27 1 {os.major(device)}:{os.minor(device)} / /data rw,relatime shared:1 - {kind} '
        'server:/export rw\n')
    assert network_filesystem(tmp_path, mounts) is network
    assert network_filesystem(tmp_path, tmp_path / 'missing') is False
