"""
Recordings split into files and kept in bounds: size, duration, queries whole, retention.

Every file is read alone, and the bag as a whole, by the independent ``rosbags``; files are
split by an injected clock rather than by waiting.
"""

from dataclasses import replace
import json
import time

from mcap.reader import make_reader
import numpy as np
import pytest
from rclpy.serialization import serialize_message
from rosbags.rosbag2 import Reader
from std_msgs.msg import String

from wafer_planner_ros.cell.model import default_cell_path
from wafer_planner_ros.cli.common import run
from wafer_planner_ros.cli.replay import main as replay_main
from wafer_planner_ros.errors import PlanningError
from wafer_planner_ros.node import messages
from wafer_planner_ros.node.recording import Loaded, NodeRecording
from wafer_planner_ros.planner import Planner
from wafer_planner_ros.recording.bag import bag_files, qos, Topic
from wafer_planner_ros.recording.queries import queries
from wafer_planner_ros.recording.reading import read, read_file
from wafer_planner_ros.recording.recorder import bag_name, Limits, Recorder
from wafer_planner_ros.recording.recover import recover
from wafer_planner_ros.roadmap.graph import RoadmapSettings
from wafer_planner_ros.service import cdr
import yaml

STATION = '/wafer_planner/plan_station_request'
TRAJECTORY = '/wafer_planner/trajectory'
RESULT = '/wafer_planner/result'
MARKERS = '/wafer_planner/roadmap_markers'
TOPICS = (Topic(STATION, 'std_msgs/msg/String', qos(keep_all=True, depth=1000)),
          Topic(TRAJECTORY, 'trajectory_msgs/msg/JointTrajectory'),
          Topic(RESULT, 'diagnostic_msgs/msg/DiagnosticStatus'),
          Topic(MARKERS, 'std_msgs/msg/String', qos(depth=1, transient_local=True)))
SECOND = 10 ** 9


class Clock:
    """A clock that moves only when told (ns since the epoch)."""

    def __init__(self):
        self.now = 1_700_000_000 * SECOND

    def __call__(self) -> int:
        return self.now

    def advance(self, seconds: float) -> None:
        self.now += int(seconds * SECOND)


def request(k: int) -> bytes:
    return serialize_message(String(data=json.dumps({'id': f'r{k}', 'from': 'a', 'to': 'b'})))


def answer(k: int, points: int = 40):
    """Return the trajectory and result of query ``k`` (random, hardly compressible)."""
    rng = np.random.default_rng(k)
    rows = [rng.normal(size=(points, 3)) for _ in range(3)]
    trajectory = cdr.joint_trajectory(k, 0, f'r{k}', ['a', 'b', 'c'],
                                      np.arange(points) * 0.01, *rows)
    return [(TRAJECTORY, trajectory),
            (RESULT, messages.result_status(f'r{k}', 'ok', 'ok', {'code': 'OK'}))]


def group(k: int, when: int, points: int = 40):
    """Return query ``k`` as ``write_now`` takes it: its request, trajectory and result."""
    return [(STATION, request(k), when, when, k)] + [
        (topic, data, when + 1000, when + 1000, k) for topic, data in answer(k, points)]


def by_file(bag):
    """Return, per file of ``bag`` read alone by rosbags, the (topic, sequence) it holds."""
    found = {}
    for file in bag_files(bag):
        with open(file, 'rb') as stream:
            sequences = [(channel.topic, message.sequence) for _, channel, message
                         in make_reader(stream).iter_messages()]
        with Reader(file) as reader:  # an indexed file that the independent reader opens
            assert reader.message_count == len(sequences)
            assert len(list(reader.messages())) == len(sequences)
        found[file.name] = sequences
    return found


def assert_queries_whole(files) -> None:
    """Assert each query is in one file only, with its request and its answer."""
    owner = {}
    for name, sequences in files.items():
        numbers = {s for topic, s in sequences if topic != MARKERS}
        for number in numbers:
            assert number not in owner, f'query {number} in {owner.get(number)} and {name}'
            owner[number] = name
            topics = sorted(topic for topic, s in sequences if s == number)
            assert topics == sorted([STATION, TRAJECTORY, RESULT]), (name, number, topics)


@pytest.mark.parametrize('points', [40, 400])
def test_split_by_size_keeps_every_file_under_the_limit_and_readable_alone(tmp_path, points):
    """Queries of 3 KB and of 30 KB (a fifth of a file): no file over, none far under."""
    limit, count = (48 if points == 40 else 160) * 1024, 80
    recorder = Recorder(tmp_path / 'bag', TOPICS, limits=Limits(max_bag_size=limit))
    sizes = []
    for k in range(1, count + 1):
        assert recorder.write_now(group(k, k * SECOND, points))
        sizes.append(len(b''.join(m[1] for m in group(k, 0, points))))
    assert recorder.close() == tmp_path / 'bag' / 'metadata.yaml'
    files = bag_files(tmp_path / 'bag')
    assert [f.name for f in files] == [f'bag_{i}.mcap' for i in range(len(files))]
    assert len(files) >= 4
    for file in files:
        assert file.stat().st_size <= limit, file
    for file in files[:-1]:  # full, save for a query that did not fit
        assert file.stat().st_size > limit - 2 * max(sizes), file
    contents = by_file(tmp_path / 'bag')
    assert_queries_whole(contents)
    assert sorted(s for names in contents.values() for _, s in names) == \
        sorted(list(range(1, count + 1)) * 3)
    # metadata.yaml lists every file as rosbag2 does, with its own times and counts.
    info = yaml.safe_load((tmp_path / 'bag' / 'metadata.yaml').read_text())[
        'rosbag2_bagfile_information']
    assert info['relative_file_paths'] == [f.name for f in files]
    assert [f['path'] for f in info['files']] == [f.name for f in files]
    for entry, file in zip(info['files'], files):
        with open(file, 'rb') as stream:
            times = [m.log_time for _, _, m in make_reader(stream).iter_messages()]
        assert entry['message_count'] == len(contents[file.name]) == len(times)
        assert entry['starting_time']['nanoseconds_since_epoch'] == min(times)
        assert entry['duration']['nanoseconds'] == max(times) - min(times)
    assert info['message_count'] == 3 * count
    assert info['starting_time']['nanoseconds_since_epoch'] == SECOND
    with Reader(tmp_path / 'bag') as reader:
        assert reader.message_count == 3 * count
        assert {c.topic: c.msgcount for c in reader.connections} == \
            {STATION: count, TRAJECTORY: count, RESULT: count, MARKERS: 0}
        assert sum(1 for _ in reader.messages()) == 3 * count
    # Read as one: every query once, in order.
    assert [q.number for q in queries(read(tmp_path / 'bag'))] == list(range(1, count + 1))


def test_split_by_duration_on_the_clock(tmp_path):
    clock = Clock()
    limits = Limits(max_bag_duration=25.0)
    recorder = Recorder(tmp_path / 'bag', TOPICS, limits=limits, clock=clock)
    for k in range(1, 11):
        assert recorder.write_now(group(k, clock()))
        clock.advance(10.0)  # a query every 10 s: the fourth finds its file 30 s old
    recorder.close()
    contents = by_file(tmp_path / 'bag')
    assert [sorted({s for _, s in found}) for found in contents.values()] == \
        [[1, 2, 3], [4, 5, 6], [7, 8, 9], [10]]
    assert_queries_whole(contents)


def test_limits_are_read_again_before_every_query(tmp_path):
    """A parameter set at run time applies from the next query on; 0 stops splitting."""
    clock, limits = Clock(), [Limits()]
    recorder = Recorder(tmp_path / 'bag', TOPICS, limits=lambda: limits[0], clock=clock)
    for k in range(1, 4):
        recorder.write_now(group(k, clock()))
        clock.advance(60.0)
    limits[0] = Limits(max_bag_duration=30.0)
    for k in range(4, 7):
        recorder.write_now(group(k, clock()))
        clock.advance(60.0)
    limits[0] = Limits()
    for k in range(7, 10):
        recorder.write_now(group(k, clock()))
        clock.advance(60.0)
    recorder.close()
    assert [sorted({s for _, s in found}) for found in by_file(tmp_path / 'bag').values()] \
        == [[1, 2, 3], [4], [5], [6, 7, 8, 9]]


def _loaded(clock) -> Loaded:
    return Loaded(default_cell_path().read_bytes(), {
        'cell': 'efem-3lp-2ll', 'roadmap_hash': 'abc123', 'roadmap_nodes': '1500',
        'roadmap_seed': '0'}, clock())


def test_a_load_while_the_first_file_is_begun_is_in_that_file(tmp_path, monkeypatch):
    # A roadmap load and new parameters that arrive after the first file's preamble was
    # taken, before the recording is in place, are written right after it.
    clock = Clock()
    recording = NodeRecording('wafer_planner', TOPICS, MARKERS, print, Limits, clock)
    recording.parameters({'trajectory.sample_period': 0.01})
    recording.loaded(_loaded(clock))
    taken = NodeRecording._preamble

    def preamble_then_changes(self, since):
        made = taken(self, since)
        self.loaded(replace(_loaded(clock), values={'roadmap_hash': 'def456'}))
        self.parameters({'trajectory.sample_period': 0.02})
        return made

    monkeypatch.setattr(NodeRecording, '_preamble', preamble_then_changes)
    bag = recording.start(tmp_path)
    recording.stop()
    (file,) = bag_files(bag)
    part = read_file(file)
    hashes = [dict(m.metadata).get('roadmap_hash') for m in part.metadata]
    assert hashes == ['abc123', 'def456']
    assert [a.name for a in part.attachments].count('parameters.yaml') == 2


def test_queued_requests_are_never_torn_from_their_answers(tmp_path):
    """Requests of later queries arrive while earlier ones are planned, answers out of order."""
    clock = Clock()
    recording = NodeRecording('wafer_planner', TOPICS, MARKERS, print,
                              lambda: Limits(max_bag_size=40 * 1024), clock)
    recording.parameters({'trajectory.sample_period': 0.01})
    recording.loaded(_loaded(clock))
    recording.markers(serialize_message(String(data='markers ' * 200)))
    bag = recording.start(tmp_path)
    rng = np.random.default_rng(3)
    waiting, number, changed_at = [], 0, None
    for _ in range(40):
        for _ in range(int(rng.integers(0, 4))):  # 0-3 requests arrive
            number += 1
            recording.request(STATION, request(number), number, {})
            waiting.append(number)
            clock.advance(0.1)
        if waiting:  # one answer goes out, not always the oldest's
            done = waiting.pop(int(rng.integers(0, min(3, len(waiting)))))
            assert recording.answer(done, answer(done)) is True
            clock.advance(0.2)
        if number >= 30 and changed_at is None:  # a change while some wait
            changed_at = clock()
            recording.parameters({'trajectory.sample_period': 0.02})
    unanswered = list(waiting)
    assert len(unanswered) >= 2
    assert recording.stop() == (bag, '')
    contents = by_file(bag)
    assert len(contents) >= 3
    owner = {}
    for name, found in contents.items():
        for topic, sequence in found:
            if topic != MARKERS:
                assert owner.setdefault(sequence, name) == name, sequence
        assert (MARKERS, 0) in found  # each file readable alone: markers, cell, parameters
        alone = read_file(bag / name)
        assert {a.name for a in alone.attachments} >= {'cell.yaml', 'parameters.yaml'}
        for query in queries(alone):  # with the parameters in force when it arrived
            assert query.load is not None and query.load.roadmap_hash == 'abc123'
            expected = 0.02 if query.received_ns >= changed_at else 0.01
            assert query.parameters['trajectory.sample_period'] == expected, query.number
    assert sorted(owner) == list(range(1, number + 1))
    found = queries(read(bag))
    assert [q.number for q in found] == list(range(1, number + 1))  # once each, in order
    assert [q.number for q in found if q.result is None] == sorted(unanswered)
    with Reader(bag) as reader:
        assert {c.topic: c.msgcount for c in reader.connections}[STATION] == number


def _session(directory, queries_count: int, limit: int, clock, keep: int = 0) -> Recorder:
    recorder = Recorder(directory, TOPICS, limits=Limits(limit, 0.0, keep), clock=clock)
    for k in range(1, queries_count + 1):
        assert recorder.write_now(group(k, clock()))
        clock.advance(1.0)
    return recorder


def _all_files(parent):
    return sorted(f for bag in parent.iterdir() if bag.is_dir() for f in bag_files(bag))


def test_retention_keeps_the_newest_files_and_never_the_one_being_written(tmp_path):
    clock, limit, keep = Clock(), 32 * 1024, 5
    older = []
    for _ in range(2):  # two earlier runs, closed, with 3+ files each
        older.append(tmp_path / bag_name('wafer_planner', clock() / SECOND))
        _session(older[-1], 30, limit, clock).close()
        clock.advance(100.0)
    other = tmp_path / bag_name('other_node', clock() / SECOND)
    _session(other, 30, limit, clock).close()  # another node's: never counted nor touched
    other_files = bag_files(other)
    before = [f for bag in older for f in bag_files(bag)]
    assert len(before) >= 6
    current = tmp_path / bag_name('wafer_planner', clock() / SECOND)
    recorder = Recorder(current, TOPICS, limits=Limits(limit, 0.0, keep), clock=clock)
    largest = 0
    for k in range(1, 41):
        assert recorder.write_now(group(k, clock()))
        clock.advance(1.0)
        files = [f for f in _all_files(tmp_path) if f.parent != other]
        assert len(files) <= keep and recorder._writer.path in files
        largest = max(largest, sum(f.stat().st_size for f in files))
    state = recorder.status()
    recorder.close()
    assert largest <= keep * limit
    assert bag_files(other) == other_files
    remaining = [f for f in _all_files(tmp_path) if f.parent != other]
    assert len(remaining) == keep and state['removed'] == len(before) + state['files'] - keep
    assert remaining == sorted(remaining, key=lambda f: (f.parent.name, f.name))
    # The oldest went first: the first run is gone, directory and all.
    assert not older[0].exists()
    for bag in [b for b in older + [current] if b.exists()]:
        info = yaml.safe_load((bag / 'metadata.yaml').read_text())[
            'rosbag2_bagfile_information']
        assert info['relative_file_paths'] == [f.name for f in bag_files(bag)]
        with Reader(bag) as reader:  # rosbags refuses a bag whose listed files are gone
            assert reader.message_count == info['message_count'] == sum(
                len(found) for found in by_file(bag).values())
        assert_queries_whole(by_file(bag))


def test_keep_one_leaves_only_the_file_being_written(tmp_path):
    clock = Clock()
    bag = tmp_path / bag_name('wafer_planner', clock() / SECOND)
    recorder = _session(bag, 30, 24 * 1024, clock, keep=1)
    assert bag_files(bag) == [recorder._writer.path]
    assert recorder._writer.path.name != f'{bag.name}_0.mcap'
    recorder.close()
    with Reader(bag) as reader:
        assert reader.message_count > 0


def test_recover_completes_a_killed_split_run_whose_oldest_files_were_removed(tmp_path):
    clock = Clock()
    bag = tmp_path / 'bag'
    recorder = _session(bag, 40, 24 * 1024, clock)
    recorder.write_now([], flush=True)
    recorder._writer.abandon()  # killed: the last file has no summary, index nor footer
    files = bag_files(bag)
    assert len(files) >= 4 and not (bag / 'metadata.yaml').exists()
    written = by_file_linear(bag)
    files[0].unlink()  # as retention does
    del written[files[0].name]
    recovered = recover(bag)
    assert not recovered.complete and recovered.cut_files == [files[-1]]
    assert (bag / (files[-1].name + '.cut')).is_file()
    assert by_file(bag) == written  # every file complete now, the same records
    with Reader(bag) as reader:
        assert reader.message_count == sum(len(found) for found in written.values())
    assert recover(bag).complete  # nothing left to do


def test_recover_sets_aside_a_file_killed_as_it_was_started(tmp_path):
    clock = Clock()
    bag = tmp_path / 'bag'
    recorder = _session(bag, 20, 24 * 1024, clock)
    recorder.write_now([], flush=True)
    recorder._writer.abandon()
    last = bag_files(bag)[-1]
    last.write_bytes(last.read_bytes()[:5])  # not even its header
    written = by_file_linear(bag)
    recovered = recover(bag)
    assert last in recovered.cut_files and not last.exists()
    assert (bag / (last.name + '.cut')).is_file()
    with Reader(bag) as reader:
        assert reader.message_count == sum(len(found) for found in written.values())


def by_file_linear(bag):
    """Return per file the (topic, sequence) a linear read finds (cut files too)."""
    found = {}
    for file in bag_files(bag):
        try:
            recording = read_file(file)
        except Exception:  # noqa: B902 - not even a header: nothing in it
            continue
        found[file.name] = [(recording.channels[m.channel_id].topic, m.sequence)
                            for m in recording.messages]
    return found


ROADMAP_TOPICS = (Topic(STATION, 'std_msgs/msg/String'),
                  Topic(TRAJECTORY, 'trajectory_msgs/msg/JointTrajectory'),
                  Topic(RESULT, 'diagnostic_msgs/msg/DiagnosticStatus'),
                  Topic(MARKERS, 'visualization_msgs/msg/MarkerArray'))
PAIRS = [('loadport1', 'loadlock1'), ('loadlock2', 'loadport3'), ('loadport2', 'nowhere'),
         ('loadport3', 'loadlock2'), ('loadlock1', 'loadport2', 'empty'),
         ('loadport1', 'loadlock2'), ('loadlock2', 'loadport1'), ('loadport2', 'loadlock1')]
"""(from, to[, load]): an empty move replays as one, or its cycle time would differ."""


@pytest.fixture(scope='module')
def split_bag(tmp_path_factory, default_cell, default_roadmap):
    """Return a recording of real plans, split into several files."""
    planner = Planner(default_cell, default_roadmap)
    roadmap = default_roadmap
    recording = NodeRecording('wafer_planner', ROADMAP_TOPICS, MARKERS, print,
                              lambda: Limits(max_bag_size=96 * 1024))
    recording.parameters({'trajectory.sample_period': 0.01})
    recording.loaded(Loaded(default_cell_path().read_bytes(), {
        'cell': default_cell.name, 'cell_file': str(default_cell_path()),
        'roadmap_hash': roadmap.digest, 'roadmap_nodes': str(RoadmapSettings().nodes),
        'roadmap_seed': str(roadmap.seed)}, time.time_ns()))
    bag = recording.start(tmp_path_factory.mktemp('split'))
    for number, (start, goal, *load) in enumerate(PAIRS, 1):
        request = {'id': f'q{number}', 'from': start, 'to': goal}
        request.update({'load': load[0]} if load else {})
        recording.request(STATION, serialize_message(String(data=json.dumps(request))),
                          number, {})
        try:
            result = planner.plan(start, goal, load=load[0] if load else None)
        except PlanningError as exc:
            out = [(RESULT, messages.result_status(
                f'q{number}', 'error', f'{exc.code.value}: {exc.message}',
                messages.error_values(exc.code.value, roadmap, start, goal, 0.2)))]
        else:
            out = [(TRAJECTORY, cdr.joint_trajectory(
                0, 0, f'q{number}', default_cell.robot.joint_names, result.times,
                result.positions, result.velocities, result.accelerations)),
                (RESULT, messages.result_status(
                    f'q{number}', 'ok', 'ok', messages.plan_values(result, roadmap, start,
                                                                   goal)))]
        assert recording.answer(number, out)
    assert recording.stop() == (bag, '')
    assert len(bag_files(bag)) >= 3
    return bag


def _replay(capsys, bag, roadmap_cache):
    code = run(replay_main, [str(bag), '--compare', '--cache-dir', str(roadmap_cache)])
    out, err = capsys.readouterr()
    return code, out + err


def test_replay_reproduces_a_split_recording(split_bag, roadmap_cache, capsys):
    code, out = _replay(capsys, split_bag, roadmap_cache)
    assert code == 0, out
    assert f'{len(PAIRS)} queries: {len(PAIRS)} reproduced, 0 different' in out


def test_replay_reproduces_what_retention_left(split_bag, roadmap_cache, capsys, tmp_path):
    left = tmp_path / split_bag.name
    left.mkdir()
    kept = bag_files(split_bag)[1:]  # the oldest file removed
    for file in kept:
        (left / file.name).write_bytes(file.read_bytes())
    numbers = sorted({q.number for q in queries(read(left))})
    assert 0 < len(numbers) < len(PAIRS) and numbers == list(range(numbers[0], len(PAIRS) + 1))
    code, out = _replay(capsys, left, roadmap_cache)
    assert code == 0, out
    assert f'{len(numbers)} queries: {len(numbers)} reproduced, 0 different' in out
