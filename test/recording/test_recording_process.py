"""
Recordings made by the node as its own process, read back by the independent ``rosbags``.

The node is stopped cleanly (SIGINT, SIGTERM) or killed (SIGKILL, then ``wafer-recover``),
and its recording is replayed offline.
"""

from collections import Counter
import os
import signal
import subprocess
import sys
import time

from mcap.reader import make_reader
from node_harness import isolate_dds, Peer, wait_for
import pytest
import rclpy
from rosbags.rosbag2 import Reader
from sessions import mixed_requests, read_with_rosbags

REQUEST_TOPICS = ('/wafer_planner/plan_station_request', '/wafer_planner/plan_request')


def record_session(tmp_path, roadmap_cache, cell, stop: signal.Signals, *parameters: str):
    """Run the node, send 50 mixed requests, stop it with ``stop`` after the 50th result."""
    isolate_dds(tmp_path)
    recordings = tmp_path / 'recordings'
    node = subprocess.Popen(
        [sys.executable, '-m', 'wafer_planner_ros.node.planner_node', '--ros-args',
         '-p', 'planning.station_table:=false', '-p', 'planning.optimise_budget:=0.0',
         '-p', f'roadmap.cache_dir:={roadmap_cache}', '-p', f'recording.directory:={recordings}',
         '-p', 'planning.timeout:=60.0', '-p', 'planning.max_queue:=100',
         *(item for parameter in parameters for item in ('-p', parameter))],
        env=dict(os.environ), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    context = rclpy.Context()
    rclpy.init(context=context)
    peer = None
    try:
        peer = Peer(context)
        requests = mixed_requests(cell)
        for kind, message, _ in requests:
            (peer.station_pub if kind == 'station' else peer.joint_pub).publish(message)
            time.sleep(0.02)
        wait_for(lambda: len(peer.results) >= len(requests), 300)
        node.send_signal(stop)
        output, _ = node.communicate(timeout=60)
    except AssertionError as exc:  # say what the node was doing
        node.kill()
        raise AssertionError(f'{exc}; the node printed:\n{node.communicate()[0][-4000:]}') \
            from None
    finally:
        if node.poll() is None:
            node.kill()
            node.communicate()
        if peer is not None:
            peer.close()
        rclpy.try_shutdown(context=context)
    bags = list(recordings.iterdir())
    assert len(bags) == 1, bags
    return bags[0], peer, output, node.returncode


def check_complete(bag, peer, count: int = 50, files: int = 1) -> None:
    """Assert the bag holds every request, result and trajectory the peer saw (once)."""
    messages = read_with_rosbags(bag)
    assert sum(len(messages[topic]) for topic in REQUEST_TOPICS) == count
    results = messages['/wafer_planner/result']
    assert len(results) == count
    assert Counter(r.name for r in results) == Counter(r.name for r in peer.results)
    assert Counter((r.name, r.message) for r in results) == \
        Counter((r.name, r.message) for r in peer.results)
    planned = sorted(r.name for r in peer.results if r.level in (b'\x00', b'\x01'))
    assert len(planned) >= count // 3
    assert sorted(t.header.frame_id for t in messages['/wafer_planner/trajectory']) == planned
    recorded = {t.header.frame_id: t for t in messages['/wafer_planner/trajectory']}
    for sent in peer.trajectories:
        got = recorded[sent.header.frame_id]
        assert [list(p.positions) for p in got.points] == \
            [list(p.positions) for p in sent.points]
    assert len(messages['/wafer_planner/roadmap_markers']) == files  # once in each file


def replay(bag, roadmap_cache):
    """Run ``wafer-replay --compare`` on the bag."""
    return subprocess.run([sys.executable, '-m', 'wafer_planner_ros.cli.replay', str(bag),
                           '--compare', '--cache-dir', str(roadmap_cache)],
                          capture_output=True, text=True, timeout=600)


@pytest.mark.slow
@pytest.mark.parametrize('stop', [signal.SIGINT, signal.SIGTERM], ids=['SIGINT', 'SIGTERM'])
def test_a_stopped_node_leaves_a_complete_recording(tmp_path, roadmap_cache, default_cell,
                                                    stop):
    bag, peer, output, code = record_session(tmp_path, roadmap_cache, default_cell, stop)
    assert code == 0, output
    assert (bag / 'metadata.yaml').is_file()
    assert 'recording closed' in output
    check_complete(bag, peer)
    if stop == signal.SIGINT:
        replayed = replay(bag, roadmap_cache)
        assert replayed.returncode == 0, replayed.stdout + replayed.stderr
        planned = sum(r.level in (b'\x00', b'\x01') for r in peer.results)
        assert '0 different' in replayed.stdout
        reproduced = int(replayed.stdout.split('50 queries: ')[1].split()[0])
        assert reproduced >= planned  # every plan, and the bad requests' errors too
        review = subprocess.run([sys.executable, '-m', 'wafer_planner_ros.cli.review',
                                 str(bag), '--out', str(tmp_path / 'review'), '--dpi', '30'],
                                capture_output=True, text=True, timeout=600)
        assert review.returncode == 0, review.stdout + review.stderr
        assert len(list((tmp_path / 'review').glob('query_*.png'))) == 50
        index = (tmp_path / 'review' / 'index.html').read_text()
        assert all(f'>{r.name}<' in index for r in peer.results if r.name)


@pytest.mark.slow
def test_a_killed_node_leaves_a_recording_that_recover_completes(tmp_path, roadmap_cache,
                                                                 default_cell):
    bag, peer, output, code = record_session(tmp_path, roadmap_cache, default_cell,
                                             signal.SIGKILL)
    assert code == -signal.SIGKILL
    assert not (bag / 'metadata.yaml').exists()
    with pytest.raises(Exception):  # noqa: B017 - rosbags refuses a cut bag, whatever the kind
        read_with_rosbags(bag)
    recovered = subprocess.run([sys.executable, '-m', 'wafer_planner_ros.cli.recover',
                                str(bag)], capture_output=True, text=True, timeout=300)
    assert recovered.returncode == 0, recovered.stdout + recovered.stderr
    assert 'cut off' in recovered.stdout
    check_complete(bag, peer)
    replayed = replay(bag, roadmap_cache)
    assert replayed.returncode == 0, replayed.stdout + replayed.stderr


@pytest.mark.slow
def test_a_killed_node_leaves_a_split_recording_that_recover_completes(tmp_path, roadmap_cache,
                                                                       default_cell):
    """
    1 MiB files, 2 ms samples (up to 0.65 MB an answer): several files, no query torn.

    (A file holds at least one query: one larger than a file would make it larger.)
    """
    bag, peer, output, code = record_session(
        tmp_path, roadmap_cache, default_cell, signal.SIGKILL,
        'recording.max_bag_size:=1048576', 'trajectory.sample_period:=0.002')
    assert code == -signal.SIGKILL
    recovered = subprocess.run([sys.executable, '-m', 'wafer_planner_ros.cli.recover',
                                str(bag)], capture_output=True, text=True, timeout=300)
    assert recovered.returncode == 0, recovered.stdout + recovered.stderr
    assert 'cut off' in recovered.stdout
    files = sorted(bag.glob('*.mcap'), key=lambda f: int(f.stem.rsplit('_', 1)[1]))
    assert len(files) >= 3, files
    owner = {}
    for file in files:
        assert file.stat().st_size <= 1048576, file
        with Reader(file) as reader:  # each file alone
            assert reader.message_count > 0
        with open(file, 'rb') as stream:
            for _, channel, message in make_reader(stream).iter_messages():
                if message.sequence:  # a query's request and answers: all in one file
                    assert owner.setdefault(message.sequence, file) == file, message.sequence
    check_complete(bag, peer, files=len(files))
    replayed = replay(bag, roadmap_cache)
    assert replayed.returncode == 0, replayed.stdout + replayed.stderr
    assert '0 different' in replayed.stdout
