"""The recording core without ROS: layout, definitions, failures, cut files and recovery."""

import errno
import io
import threading
import time

import numpy as np
import pytest
from rclpy.serialization import serialize_message
from rosbags.rosbag2 import Reader
from rosbags.typesys import get_typestore, Stores
from rosbags.typesys.msg import get_types_from_msg
from std_msgs.msg import String

from wafer_planner_ros.node.cdr import joint_trajectory
from wafer_planner_ros.recording import msgdefs
from wafer_planner_ros.recording.bag import bag_file, qos, Topic
from wafer_planner_ros.recording.reading import read, RecordingError
from wafer_planner_ros.recording.recorder import Recorder
from wafer_planner_ros.recording.recover import recover

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
    safe = [recorder.write_now([(TOPICS[0].name, serialize_message(String(data='x' * 500)),
                                 k, k, k)]) for k in range(1, 30)]
    # Answered at once either way: True while the disk had room, then False.
    first_failure = safe.index(False)
    assert first_failure >= 10 and not any(safe[first_failure:])
    assert recorder.close() is None
    assert len(errors) == 1 and 'No space left on device' in errors[0]
    assert 'No space left on device' in recorder.status()['error']
    assert recorder.status()['dropped'] > 0
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
