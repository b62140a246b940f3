"""
Benchmark: a simulated day of recording, split into small files and kept in bounds.

20,000 queries in a day of 24 simulated hours (a clock the recording is given, no waiting),
through the node's own ``NodeRecording`` and ``Recorder`` (no ROS node; the bytes are the
node's: real requests, and the trajectories and results of real plans of the default cell,
the 12 station pairs and 8 free joint pairs, each query with its own id). Requests arrive
at random (a burst now and then), so later requests wait while earlier ones are planned
and answers go out after them, as in the node's queue. The day has three node runs (two
restarts); files are split at ``--max-bag-size`` (2 MiB) and every simulated hour, and
``--keep`` (6) files are kept. Reported: files written and removed, the largest total size
of the recording directory after any query against keep x max_bag_size, every file left
read alone and every recording read whole by ``rosbags``, no query torn or repeated, the
size of a start without queries, and ``wafer-replay --compare`` of the last run (its
split files). Writes ``bench/results/recording.json``. Usage: ``python
bench/bench_recording.py [--queries N] [--max-bag-size BYTES] [--keep N]``.
"""

import argparse
from collections import Counter
import json
import os
from pathlib import Path
import subprocess
import sys
import tempfile
import time

from bench_plan import random_pairs  # bench/ is the script's folder, first on sys.path
from builtin_interfaces.msg import Time
from mcap.reader import make_reader
import numpy as np
from rclpy.serialization import serialize_message
from rosbags.rosbag2 import Reader
from std_msgs.msg import String
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from wafer_planner_ros.cell.model import Cell, default_cell_path
from wafer_planner_ros.cell.stations import station_pairs
from wafer_planner_ros.node import messages
from wafer_planner_ros.node.markers import roadmap_markers
from wafer_planner_ros.node.recording import Loaded, NodeRecording
from wafer_planner_ros.planner import Planner
from wafer_planner_ros.recording.bag import bag_files, qos, Topic
from wafer_planner_ros.recording.recorder import Limits
from wafer_planner_ros.roadmap.cache import DEFAULT_CACHE_DIR, load_or_build
from wafer_planner_ros.roadmap.graph import RoadmapSettings
from wafer_planner_ros.service import cdr

RESULTS = Path(__file__).resolve().parent / 'results' / 'recording.json'
NODE = 'wafer_planner'
STATION = f'/{NODE}/plan_station_request'
JOINT = f'/{NODE}/plan_request'
TRAJECTORY = f'/{NODE}/trajectory'
RESULT = f'/{NODE}/result'
MARKERS = f'/{NODE}/roadmap_markers'
TOPICS = (Topic(JOINT, 'trajectory_msgs/msg/JointTrajectory', qos(keep_all=True, depth=1000)),
          Topic(STATION, 'std_msgs/msg/String', qos(keep_all=True, depth=1000)),
          Topic(TRAJECTORY, 'trajectory_msgs/msg/JointTrajectory'),
          Topic(RESULT, 'diagnostic_msgs/msg/DiagnosticStatus'),
          Topic(MARKERS, 'visualization_msgs/msg/MarkerArray', qos(depth=1, transient_local=True)))
DAY = 86400.0
SECOND = 10 ** 9


class Clock:
    """The simulated time (ns since the epoch), moved by the simulation alone."""

    def __init__(self):
        self.now = 1_767_225_600 * SECOND  # 2026-01-01 00:00 UTC

    def __call__(self) -> int:
        return self.now


def plans(cell, roadmap) -> list:
    """Return (kind, start, goal, result) for the station pairs and some joint pairs."""
    planner = Planner(cell, roadmap)
    found = []
    for kind, start, goal in ([('station', a, b) for a, b in station_pairs(cell)]
                              + [('joint', a, b) for a, b in random_pairs(cell, 8)]):
        found.append((kind, start, goal, planner.plan(start, goal)))
    return found


def query_bytes(cell, roadmap, plan, request_id: str):
    """Return (request topic, request bytes, answer [(topic, bytes)]) of one query."""
    kind, start, goal, result = plan
    if kind == 'station':
        topic = STATION
        request = serialize_message(String(data=json.dumps(
            {'id': request_id, 'from': start, 'to': goal})))
    else:
        topic = JOINT
        message = JointTrajectory(joint_names=list(cell.robot.joint_names), points=[
            JointTrajectoryPoint(positions=[float(v) for v in q]) for q in (start, goal)])
        message.header.frame_id = request_id
        request = serialize_message(message)
    answer = [(TRAJECTORY, cdr.joint_trajectory(
        0, 0, request_id, cell.robot.joint_names, result.times, result.positions,
        result.velocities, result.accelerations)),
        (RESULT, messages.result_status(request_id, 'ok', 'ok', messages.plan_values(
            result, roadmap, start, goal)))]
    return topic, request, answer


def events(rng, count: int, start_ns: int, span: float) -> list:
    """
    Return (time ns, 'request' or 'answer', query) for ``count`` queries over ``span`` s.

    Arrivals at random (one in 50 brings a burst of 6 at once); one planner, first come
    first served, 20-300 ms each: requests that arrive meanwhile wait.
    """
    gaps = rng.exponential(span / count, count)
    gaps[rng.random(count) < 0.12] = 0.005  # bursts: several at once
    arrivals = start_ns + np.cumsum(gaps * SECOND).astype(np.int64)
    done, found = start_ns, []
    for k, arrival in enumerate(arrivals):
        done = max(done, int(arrival)) + int(rng.uniform(0.02, 0.3) * SECOND)
        found += [(int(arrival), 0, k), (done, 1, k)]
    return [(t, 'request' if e == 0 else 'answer', k) for t, e, k in sorted(found)]


def directory_bytes(parent: Path) -> tuple:
    """Return (bytes of the MCAP files, bytes of everything, MCAP files) under ``parent``."""
    mcap = total = files = 0
    for bag in os.scandir(parent):
        if bag.is_dir():
            for entry in os.scandir(bag.path):
                size = entry.stat().st_size
                total += size
                if entry.name.endswith('.mcap'):
                    mcap, files = mcap + size, files + 1
    return mcap, total, files


def run_day(parent: Path, cell, roadmap, pool, args) -> dict:
    """Record the day in three runs; return the figures."""
    clock, rng = Clock(), np.random.default_rng(2026)
    limits = Limits(args.max_bag_size, args.max_bag_duration, args.keep)
    markers = serialize_message(roadmap_markers(cell, roadmap, 'efem', Time()))
    last = min(300, args.queries // 3)  # replayed: small enough to re-plan in seconds
    runs = [(args.queries - last) // 2, args.queries - last - (args.queries - last) // 2, last]
    largest = {'mcap_bytes': 0, 'all_bytes': 0, 'files': 0}
    bags, written, removed, seconds = [], 0, 0, 0.0
    span = DAY / args.queries
    for run, count in enumerate(runs):
        clock.now += 60 * SECOND  # a restart
        recording = NodeRecording(NODE, TOPICS, MARKERS, print, lambda: limits, clock)
        recording.parameters({'trajectory.sample_period': 0.01, 'planning.optimise_budget': 0.0})
        recording.loaded(Loaded(default_cell_path().read_bytes(), {
            'cell': cell.name, 'cell_file': str(default_cell_path()),
            'roadmap_hash': roadmap.digest, 'roadmap_nodes': str(RoadmapSettings().nodes),
            'roadmap_seed': str(roadmap.seed)}, clock()))
        recording.markers(markers)
        bags.append(recording.start(parent))
        answers = {}
        began = time.perf_counter()
        for when, what, k in events(rng, count, clock(), span * count):
            clock.now = when
            if what == 'request':
                plan = pool[int(rng.integers(len(pool)))]
                topic, request, answers[k] = query_bytes(cell, roadmap, plan, f'r{run}-{k}')
                recording.request(topic, request, k + 1, {})
                continue
            assert recording.answer(k + 1, answers.pop(k)) is True
            mcap, total, files = directory_bytes(parent)
            largest = {'mcap_bytes': max(largest['mcap_bytes'], mcap),
                       'all_bytes': max(largest['all_bytes'], total),
                       'files': max(largest['files'], files)}
        seconds += time.perf_counter() - began
        status = recording.status()
        written += status['recording_files']
        removed += status['recording_removed']
        assert recording.stop() == (bags[-1], '')
        print(f'run {run + 1}: {count} queries, {status["recording_files"]} files, '
              f'{status["recording_removed"]} removed by retention', file=sys.stderr)
    return {'bags': bags, 'largest': largest, 'files_written': written,
            'files_removed': removed, 'recording_seconds': seconds}


def check_files(parent: Path) -> dict:
    """Read every file left alone, and every recording whole, with rosbags; look for tears."""
    files, messages_alone, owner, torn, repeated = 0, 0, {}, 0, 0
    sizes = []
    for bag in sorted(p for p in parent.iterdir() if p.is_dir()):
        with Reader(bag) as reader:
            whole = sum(1 for _ in reader.messages())
            assert whole == reader.message_count
        alone = 0
        for file in bag_files(bag):
            files += 1
            sizes.append(file.stat().st_size)
            with Reader(file) as reader:
                alone += sum(1 for _ in reader.messages())
            with open(file, 'rb') as stream:
                topics = Counter()
                for _, channel, message in make_reader(stream).iter_messages():
                    if message.sequence:
                        topics[(message.sequence, channel.topic in (STATION, JOINT))] += 1
            for number in {n for n, _ in topics}:
                key = (bag.name, number)
                repeated += key in owner
                owner[key] = file.name
                torn += topics[(number, True)] != 1 or topics[(number, False)] != 2
        assert alone == whole
        messages_alone += alone
    return {'files_left': files, 'messages_read': messages_alone, 'queries_left': len(owner),
            'queries_torn': torn, 'queries_repeated': repeated,
            'largest_file_bytes': max(sizes, default=0), 'bytes_left': sum(sizes)}


def empty_start(parent: Path, cell, roadmap) -> dict:
    """Return the size of a recording started and stopped without a query."""
    clock = Clock()
    recording = NodeRecording(NODE, TOPICS, MARKERS, print, Limits, clock)
    recording.parameters({'trajectory.sample_period': 0.01})
    recording.loaded(Loaded(default_cell_path().read_bytes(), {'cell': cell.name}, clock()))
    recording.markers(serialize_message(roadmap_markers(cell, roadmap, 'efem', Time())))
    bag = recording.start(parent)
    recording.stop()
    (file,) = bag_files(bag)
    with open(file, 'rb') as stream:
        summary = make_reader(stream).get_summary()
    compressed = sum(c.compressed_size for c in summary.chunk_indexes)
    uncompressed = sum(c.uncompressed_size for c in summary.chunk_indexes)
    size = file.stat().st_size
    return {'file_bytes': size, 'uncompressed_equivalent_bytes': size - compressed + uncompressed}


def replay(bag: Path) -> dict:
    """Run ``wafer-replay --compare`` on ``bag``; return its summary line and exit code."""
    began = time.perf_counter()
    done = subprocess.run([sys.executable, '-m', 'wafer_planner_ros.cli.replay', str(bag),
                           '--compare', '--cache-dir', str(DEFAULT_CACHE_DIR)],
                          capture_output=True, text=True, timeout=600)
    lines = done.stdout.strip().splitlines()
    return {'exit_code': done.returncode, 'summary': lines[-1] if lines else done.stderr[-500:],
            'files': len(bag_files(bag)), 'seconds': time.perf_counter() - began}


def main() -> int:
    """Run the benchmark."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--queries', type=int, default=20000, help='queries in the day')
    parser.add_argument('--max-bag-size', type=int, default=2 << 20, help='bytes per file')
    parser.add_argument('--max-bag-duration', type=float, default=3600.0, help='s per file')
    parser.add_argument('--keep', type=int, default=6, help='files kept')
    args = parser.parse_args()
    cell = Cell.from_yaml(default_cell_path())
    roadmap = load_or_build(cell, cache_dir=DEFAULT_CACHE_DIR).roadmap
    pool = plans(cell, roadmap)
    with tempfile.TemporaryDirectory() as temporary:
        parent = Path(temporary)
        day = run_day(parent / 'recordings', cell, roadmap, pool, args)
        files = check_files(parent / 'recordings')
        replayed = replay(day['bags'][-1])
        empty = empty_start(parent / 'empty', cell, roadmap)
    bound = args.keep * args.max_bag_size
    report = {
        'benchmark': 'a simulated day of recording through NodeRecording, default cell',
        'queries': args.queries, 'runs': 3,
        'limits': {'max_bag_size': args.max_bag_size,
                   'max_bag_duration': args.max_bag_duration, 'keep': args.keep},
        'bound_bytes': bound,
        'files_written': day['files_written'], 'files_removed': day['files_removed'],
        'largest_seen': day['largest'],
        'within_bound': day['largest']['mcap_bytes'] <= bound
        and day['largest']['files'] <= args.keep,
        'simulated_ms_per_query': 1000 * day['recording_seconds'] / args.queries,
        'bytes_per_query_left': files['bytes_left'] / max(files['queries_left'], 1),
        'left': files, 'replay_last_run': replayed, 'start_without_queries': empty,
    }
    largest = day['largest']
    print(f"{args.queries} queries in 3 runs: {day['files_written']} files written, "
          f"{day['files_removed']} removed by retention")
    print(f"largest directory seen: {largest['mcap_bytes'] / 2**20:.2f} MiB of MCAP files "
          f"({largest['all_bytes'] / 2**20:.2f} MiB with metadata.yaml), {largest['files']} "
          f'files; bound keep x max_bag_size = {bound / 2**20:.2f} MiB, {args.keep} files')
    print(f"left: {files['files_left']} files (largest {files['largest_file_bytes']} bytes), "
          f"{files['messages_read']} messages read by rosbags file by file and whole, "
          f"{files['queries_left']} queries, {files['queries_torn']} torn, "
          f"{files['queries_repeated']} repeated; "
          f"{report['bytes_per_query_left'] / 1024:.1f} KiB per query, preambles included")
    print(f"replay --compare of the last run ({replayed['files']} files): "
          f"{replayed['summary']} (exit {replayed['exit_code']}, {replayed['seconds']:.1f} s)")
    print(f"a start without queries: {empty['file_bytes']} bytes "
          f"({empty['uncompressed_equivalent_bytes']} uncompressed)")
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(report, indent=1) + '\n')
    print(f'written {RESULTS}', file=sys.stderr)
    ok = report['within_bound'] and not files['queries_torn'] and replayed['exit_code'] == 0
    return 0 if ok else 1


if __name__ == '__main__':
    sys.exit(main())
