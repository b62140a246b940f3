"""
Benchmark: a controlled stop's latency through the node, end to end, idle and while planning.

The node runs as a user runs it: a process (``python -m wafer_planner_ros.node.main``, this
checkout's code) with the packaged parameters (``--params-file config/wafer_planner.yaml``:
``planning.optimise_budget`` 0.12 s, recording on, the station table on), a fresh
``roadmap.cache_dir`` and ``recording.directory`` in temp directories, and
``planning.station_table_ports`` off: the moves through the ports take an hour or more to
plan at start-up and would share the two cores (and the status's ``busy_with``) meanwhile.
The peer (this process) waits until the station table is ready, then, for every station
pair of the default cell (``station_pairs``, 12) and each pass (``--passes``, 2), stops the
loaded move (answered from the table) at ``--moments`` (10) moments near
k T / (moments + 1) of its cycle time T, each moment twice, in alternating order, each time
on a move asked afresh and running: as a controller stops a robot now, the request goes out
when the move has run to the moment less ``--lead`` (0.05 s) and names the moment
``--lead`` after the instant it is sent (its stamp's clock), so the node answers from the
stops it made ahead of the running move where it has made that one (``braking_from`` later
than ``at``: counted as made ahead) and finds the stop for the moment itself otherwise:

(a) idle: nothing else asked (the node's status says it plans nothing, queue empty);
(b) planning: a joint request just sent (one of the 50 farthest of ``random_pairs``,
    planned by the budgeted whole-curve optimisation) and the node's ``~/get_status``
    saying ``busy_with: plan`` for it; the stop is sent a random 0-30 ms later. It counts
    only if the joint request was still being planned throughout: its result arrived after
    the stop's result and trajectory, and the stop was sent after its planning began (the
    joint result's receipt less its ``planning_time_ms``; for a ``TIMEOUT`` answer, which
    comes while it is still planned, the status is the evidence). Otherwise it is asked
    again with another joint request (the attempts are counted).

End to end: from just before the peer publishes the stop request (``~/stop_request``) to
the later of the peer's receipt of its ``~/result`` and of its trajectory (``~/trajectory``,
frame_id = the stop's id), both taken in the subscription callbacks (raw: before any
deserialising; of a trajectory the callback reads only its header, the rest read later by
the thread that needs it, so that a long move received just before does not hold the
executor while the stop's answer waits). Also per stop the result's ``node_ms`` (from the
stop thread's callback to the answer made), ``stop_ms`` and ``verify_ms``, and where the
rest goes, on the wall clock every process shares: the peer's publish, the node's DDS
receipt of the request (its recording's log time), the result's DDS source time stamp
(published: the node publishes a stop, then records it), the peer's DDS receipt and its
callback.

Whether a stop was the rest of the move (``'rest'``) is not among the result's values
(``messages.plan_values`` leaves out the stop's ``timing``); it is told apart here by its
duration: a 'rest' stop is the rest of the move, ``cycle_time`` = T - at (to 1e-9 s), while
``controlled_stop`` keeps a braked one only when it is shorter (inferred, so marked so).

Each answer's duration is also compared with the core's stop of the same move found for
that moment itself (``Planner.stop``, the whole-curve move planned here: the table's): what a
stop made ahead costs in time to rest.

Prints a table; writes ``bench/results/stop_node.json`` (every row, the summary, the
machine, the commit). Usage: ``python bench/bench_stop_node.py [--passes 2]
[--moments 10] [--pairs N] [--domain 91]``; ``--from-rows FILE`` summarises the rows of an
earlier run's file again (nothing measured).
"""

import argparse
import json
import os
from pathlib import Path
import platform
import struct
import subprocess
import sys
import tempfile
import threading
import time
from typing import Callable

from bench_plan import random_pairs  # bench/ is the script's folder, first on sys.path
from diagnostic_msgs.msg import DiagnosticStatus
import numpy as np
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.serialization import deserialize_message
from std_msgs.msg import String
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from wafer_planner_ros.cell.model import Cell, default_cell_path
from wafer_planner_ros.cell.stations import station_pairs
from wafer_planner_ros.node.qos import RELIABLE
from wafer_planner_ros.planner import Planner, PlannerSettings
from wafer_planner_ros.recording.reading import read
from wafer_planner_ros.roadmap.cache import load_or_build
from wafer_planner_ros.service.table import build_table
from wafer_planner_ros.trajectory.methods import WholeCurve

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / 'bench' / 'results' / 'stop_node.json'
PARAMS = ROOT / 'config' / 'wafer_planner.yaml'
NS = '/wafer_planner'
FAR_JOINTS = 50
"""The farthest random joint pairs kept for condition (b)."""
JITTER = 0.03
"""s: the stop is sent up to this long after the status says the joint request is planned."""
ATTEMPTS = 4
"""Joint requests tried per stop of condition (b) before it is given up."""
PLANNING_BEFORE = 0.03
"""s before the stop is due that condition (b) sends its joint request (it is being
planned 5-20 ms later, then the stop waits up to ``JITTER``)."""
TARGET_MS = 10.0
"""The issue's target: p99 end to end while a joint request is being planned."""


class Peer(Node):
    """Publishes requests; takes every answer's receipt in its callback, before deserialising."""

    def __init__(self):
        """Create the publishers, the raw subscriptions and the status client."""
        super().__init__('bench_stop_peer')
        self.lock = threading.Lock()
        self.results, self.trajectories, self.events = {}, {}, {}
        self.create_subscription(DiagnosticStatus, f'{NS}/result', self._on_result,
                                 RELIABLE, raw=True)
        self.create_subscription(JointTrajectory, f'{NS}/trajectory', self._on_trajectory,
                                 RELIABLE, raw=True)
        self.stops = self.create_publisher(String, f'{NS}/stop_request', RELIABLE)
        self.stations = self.create_publisher(String, f'{NS}/plan_station_request', RELIABLE)
        self.joints = self.create_publisher(JointTrajectory, f'{NS}/plan_request', RELIABLE)
        self.status_client = self.create_client(Trigger, f'{NS}/get_status')

    def _on_result(self, data: bytes, info) -> None:
        perf, wall = time.perf_counter(), time.time_ns()
        msg = deserialize_message(data, DiagnosticStatus)
        self._store(self.results, msg.name, {
            'perf': perf, 'wall_ns': wall, 'source_ns': info.get('source_timestamp'),
            'received_ns': info.get('received_timestamp'), 'level': msg.level,
            'message': msg.message, 'values': {kv.key: kv.value for kv in msg.values}})

    def _on_trajectory(self, data: bytes, info) -> None:
        perf, wall = time.perf_counter(), time.time_ns()
        # Only its header is read here (its id and stamp, the first fields of its CDR):
        # deserialising a move of hundreds of points would hold this executor, and the
        # next answer's receipt with it, for milliseconds (``trajectory_facts`` reads the
        # rest later, in the thread that needs it).
        if data[1] == 1:  # little-endian CDR
            sec, nanosec, size = struct.unpack_from('<iII', data, 4)
            frame_id, stamp = bytes(data[16:15 + size]).decode(), sec + 1e-9 * nanosec
        else:
            msg = deserialize_message(data, JointTrajectory)
            frame_id = msg.header.frame_id
            stamp = msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec
        self._store(self.trajectories, frame_id, {
            'perf': perf, 'wall_ns': wall, 'source_ns': info.get('source_timestamp'),
            'received_ns': info.get('received_timestamp'), 'stamp': stamp, 'data': data})

    def _store(self, inbox: dict, key: str, entry: dict) -> None:
        with self.lock:
            inbox.setdefault(key, entry)
            event = self.events.get(key)
            result = self.results.get(key)
            complete = result is not None and (key in self.trajectories
                                               or result['values'].get('code') != 'OK')
        if event is not None and complete:
            event.set()

    def expect(self, key: str) -> threading.Event:
        """Return the event set once ``key``'s result (and, if OK, its trajectory) arrived."""
        event = threading.Event()
        with self.lock:
            self.events[key] = event
        return event

    def done(self, key: str) -> bool:
        """Return whether ``key``'s result has arrived."""
        with self.lock:
            return key in self.results

    def status(self) -> dict:
        """Return ``~/get_status`` as a dict (sent again after 5 s unanswered)."""
        while True:
            future = self.status_client.call_async(Trigger.Request())
            if _wait(future.done, 5.0):
                return json.loads(future.result().message)
            self.status_client.remove_pending_request(future)

    def send_stop(self, stop_id: str, trajectory: str, began: float, lead: float) -> tuple:
        """
        Publish a stop request of a move that began at ``began`` (s), ``lead`` s from now.

        Return (perf counter, wall ns, at) just before it went.
        """
        at = time.time() - began + lead
        msg = String(data=json.dumps({'id': stop_id, 'trajectory': trajectory, 'at': at}))
        perf, wall = time.perf_counter(), time.time_ns()
        self.stops.publish(msg)
        return perf, wall, at

    def send_station(self, request_id: str, start: str, goal: str) -> None:
        """Publish a station request."""
        self.stations.publish(String(data=json.dumps(
            {'id': request_id, 'from': start, 'to': goal})))

    def send_joints(self, request_id: str, start, goal) -> None:
        """Publish a joint request (the robot's joint order)."""
        msg = JointTrajectory()
        msg.header.frame_id = request_id
        msg.points = [JointTrajectoryPoint(positions=[float(v) for v in start]),
                      JointTrajectoryPoint(positions=[float(v) for v in goal])]
        self.joints.publish(msg)


def trajectory_facts(entry: dict) -> dict:
    """Add a received trajectory's ``points`` and ``duration`` to its entry; return it."""
    if 'points' not in entry:
        msg = deserialize_message(entry['data'], JointTrajectory)
        last = msg.points[-1].time_from_start if msg.points else None
        entry.update(points=len(msg.points),
                     duration=last.sec + 1e-9 * last.nanosec if last is not None else 0.0)
    return entry


def _wait(predicate, timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.001)
    return True


def _ready(peer: Peer) -> float:
    """Wait for discovery, the roadmap and the station table; return the seconds waited."""
    begun = time.monotonic()
    if not _wait(lambda: peer.status_client.service_is_ready()
                 and peer.stops.get_subscription_count() > 0
                 and peer.stations.get_subscription_count() > 0
                 and peer.joints.get_subscription_count() > 0, 120.0):
        raise TimeoutError('the node was not discovered within 120 s')
    deadline = time.monotonic() + 1800.0
    while True:
        status = peer.status()
        if status['ready'] and status['station_table'] and status['busy_with'] is None:
            return time.monotonic() - begun
        if time.monotonic() > deadline:
            raise TimeoutError(f'the station table was not ready in 30 min: {status}')
        time.sleep(0.2)


def _idle(peer: Peer) -> dict:
    """Wait until the node plans nothing and nothing waits; return its status."""
    deadline = time.monotonic() + 120.0
    while True:
        status = peer.status()
        if status['busy_with'] is None and status['queue'] == 0:
            return status
        if time.monotonic() > deadline:
            raise TimeoutError(f'the node stayed busy: {status}')
        time.sleep(0.01)


def _move(peer: Peer, request_id: str, start: str, goal: str) -> dict:
    """Ask a station move; return its result values (with the trajectory's duration)."""
    event = peer.expect(request_id)
    peer.send_station(request_id, start, goal)
    if not event.wait(60.0):
        raise TimeoutError(request_id)
    values = dict(peer.results[request_id]['values'])
    if values['code'] != 'OK':
        raise RuntimeError(f'{request_id} {start} -> {goal}: {values["code"]} '
                           f'{peer.results[request_id]["message"]}')
    values['trajectory_duration'] = trajectory_facts(peer.trajectories[request_id])['duration']
    return values


def _stop(peer: Peer, stop_id: str, move_id: str, lead: float) -> dict:
    """Stop a running move ``lead`` s from now; wait for the answer; return its row (ms)."""
    event = peer.expect(stop_id)
    perf, wall, at = peer.send_stop(stop_id, move_id, peer.trajectories[move_id]['stamp'],
                                    lead)
    if not event.wait(60.0):
        raise TimeoutError(stop_id)
    result = peer.results[stop_id]
    values = result['values']
    trajectory = peer.trajectories.get(stop_id)
    if trajectory is not None:
        trajectory_facts(trajectory)
    row = {'id': stop_id, 'move': move_id, 'at': at, 'code': values['code'],
           'method': values.get('method', ''), 'sent_perf': perf, 'sent_ns': wall,
           'result_ms': 1e3 * (result['perf'] - perf),
           'result_source_ns': result['source_ns'], 'result_received_ns': result['received_ns'],
           'result_callback_ns': result['wall_ns']}
    for key in ('node_ms', 'stop_ms', 'verify_ms', 'planning_time_ms', 'cycle_time',
                'braking_from'):
        row[key] = float(values[key]) if key in values else None
    row['made_ahead'] = row['braking_from'] is not None and row['braking_from'] > at
    if trajectory is not None:
        row.update(trajectory_ms=1e3 * (trajectory['perf'] - perf),
                   trajectory_source_ns=trajectory['source_ns'],
                   trajectory_points=trajectory['points'])
        row['e2e_ms'] = max(row['result_ms'], row['trajectory_ms'])
    else:
        row['e2e_ms'] = row['result_ms']
    return row


def _running(peer: Peer, move_id: str, pair: tuple, fraction: float, before: float) -> float:
    """
    Ask a move; return its cycle time once it has run to ``fraction`` of it less ``before`` s.

    Its stamp is when it starts (the node's clock, the same wall clock as this one's).
    """
    cycle = float(_move(peer, move_id, *pair)['cycle_time'])
    began = peer.trajectories[move_id]['stamp']
    time.sleep(max(0.0, began + fraction * cycle - before - time.time()))
    return cycle


def _again(peer: Peer, move_id: str, pair: tuple, fraction: float,
           lead: float) -> Callable[[int], str]:
    """Return ``again`` for ``_busy_stop``: a fresh move ``<move_id>-<attempt>`` running."""
    def again(attempt: int) -> str:
        _running(peer, f'{move_id}-{attempt}', pair, fraction, lead + PLANNING_BEFORE)
        return f'{move_id}-{attempt}'
    return again


def _busy_stop(peer: Peer, stop_id: str, move_id: str, lead: float, far: list,
               counter: list, rng, bad: set, again: Callable[[int], str]) -> dict:
    """
    Stop while a joint request is being planned (the module); return the row.

    ``counter``: [the next joint request's number]; ``bad``: indices into ``far`` refused;
    ``again(attempt)``: the id of a move asked afresh and running to the same moment, for
    each attempt after the first (the first move has run on meanwhile).
    """
    tries = []
    for attempt in range(ATTEMPTS):
        if attempt:
            move_id = again(attempt)
        while counter[0] % len(far) in bad:
            counter[0] += 1
        index = counter[0] % len(far)
        pair, joint_id = far[index], f'j{counter[0]}'
        counter[0] += 1
        peer.send_joints(joint_id, *pair)
        begun = time.perf_counter()
        planning = None
        while not peer.done(joint_id) and time.perf_counter() - begun < 5.0:
            status = peer.status()
            if status['busy_with'] == 'plan':
                planning = (time.perf_counter() - begun, status)
                break
        if planning is None or peer.done(joint_id):
            tries.append({'joint': joint_id, 'why': 'answered before the status said plan'})
            _wait(lambda: peer.done(joint_id), 60.0)
            if peer.results[joint_id]['values']['code'] != 'OK':
                bad.add(index)  # refused at once (e.g. OUT_OF_LIMITS): not asked again
            _idle(peer)
            continue
        time.sleep(rng.uniform(0.0, JITTER))
        if peer.done(joint_id):
            tries.append({'joint': joint_id, 'why': 'answered before the stop was sent'})
            _idle(peer)
            continue
        this_id = stop_id if attempt == 0 else f'{stop_id}-{attempt}'
        row = _stop(peer, this_id, move_id, lead)
        if not _wait(lambda: peer.done(joint_id), 60.0):
            raise TimeoutError(joint_id)
        joint = peer.results[joint_id]
        code = joint['values']['code']
        planning_ms = float(joint['values'].get('planning_time_ms', 'nan'))
        answered_last = max(row['result_ms'], row.get('trajectory_ms') or 0.0) / 1e3 \
            + row['sent_perf']
        began_before = code == 'TIMEOUT' or \
            row['sent_perf'] > joint['perf'] - planning_ms / 1e3
        overlap = joint['perf'] > answered_last and began_before
        row.update(joint=joint_id, joint_code=code, joint_planning_ms=planning_ms,
                   joint_node_ms=float(joint['values'].get('node_ms', 'nan')),
                   status_plan_after_ms=1e3 * planning[0],
                   joint_answered_after_stop_ms=1e3 * (joint['perf'] - answered_last),
                   overlap=overlap, attempts=attempt + 1, failed_attempts=tries)
        _idle(peer)  # a TIMEOUT answer comes before its planning ends
        if overlap:
            return row
        tries.append({'joint': joint_id, 'stop': this_id,
                      'why': 'the joint request was answered before the stop'
                      if joint['perf'] <= answered_last else 'planning began after the stop'})
    row['overlap'] = False
    return row


def _recorded_times(directory: str) -> dict:
    """Return id -> (node's DDS receipt of the stop request, answer recorded), wall ns."""
    times = {}
    for bag in sorted(p for p in Path(directory).iterdir() if p.is_dir()):
        recording = read(bag)
        for message in recording.messages:
            topic = recording.channels[message.channel_id].topic
            if topic == f'{NS}/stop_request':
                try:
                    request_id = json.loads(deserialize_message(message.data, String).data)['id']
                except (ValueError, KeyError, TypeError):
                    continue
                times.setdefault(request_id, {})['node_received_ns'] = message.log_time
            elif topic == f'{NS}/result':
                name = deserialize_message(message.data, DiagnosticStatus).name
                times.setdefault(name, {})['recorded_ns'] = message.log_time
    return times


def _breakdown(row: dict, recorded: dict) -> None:
    """Add where the end-to-end time went (ms) to a row, from the wall-clock stamps."""
    got = recorded.get(row['id'], {})
    if 'node_received_ns' not in got or row['node_ms'] is None:
        return
    ms = 1e-6
    # The node publishes a stop first, then records it: from its receipt to its result's
    # publication, the stop thread's time less what ``node_ms`` covers (from the callback's
    # start to the answer made) is its wake-up and the answer's messages and publishing.
    inside = (row['result_source_ns'] - got['node_received_ns']) * ms
    row['split_ms'] = {
        'inbound_dds': (got['node_received_ns'] - row['sent_ns']) * ms,
        'wake_and_publish': inside - row['node_ms'],
        'stop': row['stop_ms'], 'verify': row['verify_ms'],
        'request_and_answer': row['node_ms'] - row['stop_ms'] - row['verify_ms'],
        'outbound_dds': (row['result_received_ns'] - row['result_source_ns']) * ms,
        'peer_callback': (row['result_callback_ns'] - row['result_received_ns']) * ms,
    }


def _stats(values) -> dict:
    values = np.asarray([v for v in values if v is not None], float)
    if not len(values):
        return {}
    return {'p50': float(np.percentile(values, 50)), 'p90': float(np.percentile(values, 90)),
            'p99': float(np.percentile(values, 99)), 'max': float(values.max()),
            'n': int(len(values))}


def _summary(rows: list) -> dict:
    out = {'stops': len(rows), 'codes': {}}
    for row in rows:
        out['codes'][row['code']] = out['codes'].get(row['code'], 0) + 1
        if row['code'] == 'OK' and row.get('cycle_time') is not None:
            row['rest_inferred'] = abs(row['cycle_time'] - row['rest_of_move']) <= 1e-9
    timed = [r for r in rows if 'rest_inferred' in r]
    if timed:
        rest = [r for r in timed if r['rest_inferred']]
        braked = [r for r in timed if not r['rest_inferred']]
        out['rest_share_inferred'] = len(rest) / len(timed)
        out['by_timing_inferred'] = {
            name: {key: _stats([r[key] for r in part]) for key in
                   ('e2e_ms', 'node_ms', 'stop_ms', 'verify_ms')}
            for name, part in (('rest', rest), ('braked', braked))}
    for key in ('e2e_ms', 'result_ms', 'trajectory_ms', 'node_ms', 'stop_ms', 'verify_ms'):
        out[key] = _stats([r.get(key) for r in rows])
    ahead = [r for r in rows if r.get('made_ahead')]
    out['made_ahead_share'] = len(ahead) / len(rows) if rows else None
    out['by_source'] = {name: {key: _stats([r.get(key) for r in part]) for key in
                               ('e2e_ms', 'node_ms', 'stop_ms', 'verify_ms')}
                        for name, part in (('made_ahead', ahead), ('found_for_the_moment', [
                            r for r in rows if not r.get('made_ahead')]))}
    out['outside_stop_verify_ms'] = _stats([r['e2e_ms'] - r['stop_ms'] - r['verify_ms']
                                            for r in rows if r.get('stop_ms') is not None])
    split = [r['split_ms'] for r in rows if 'split_ms' in r]
    if split:
        out['split_ms'] = {part: _stats([s[part] for s in split]) for part in split[0]}
        out['split_ms_mean'] = {part: float(np.mean([s[part] for s in split]))
                                for part in split[0]}
    return out


def _head_commit() -> str:
    try:
        return subprocess.run(['git', '-C', str(ROOT), 'rev-parse', 'HEAD'], check=True,
                              capture_output=True, text=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return ''


def main() -> int:
    """Run the benchmark; print and store the figures."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--passes', type=int, default=2)
    parser.add_argument('--moments', type=int, default=10)
    parser.add_argument('--pairs', type=int, default=0, help='the first N pairs (0: all)')
    parser.add_argument('--domain', type=int, default=91, help='ROS_DOMAIN_ID')
    parser.add_argument('--lead', type=float, default=0.05,
                        help='s between sending a stop and the moment it names')
    parser.add_argument('--from-rows', help="an earlier run's file: summarise it again")
    args = parser.parse_args()
    if args.from_rows:
        return _from_rows(args.from_rows)
    temp = Path(tempfile.mkdtemp(prefix='bench_stop_node_'))
    for sub in ('cache', 'recordings', 'ros_log'):
        (temp / sub).mkdir()
    dds = {'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST', 'ROS_DOMAIN_ID': str(args.domain),
           'ROS_LOG_DIR': str(temp / 'ros_log')}
    os.environ.update(dds)
    env = dict(os.environ, PYTHONUNBUFFERED='1', PYTHONPATH=os.pathsep.join(
        filter(None, [str(ROOT), os.environ.get('PYTHONPATH')])))
    log = open(temp / 'node.log', 'w')
    node = subprocess.Popen(
        [sys.executable, '-m', 'wafer_planner_ros.node.main', '--ros-args',
         '--params-file', str(PARAMS), '-p', f'roadmap.cache_dir:={temp / "cache"}',
         '-p', f'recording.directory:={temp / "recordings"}',
         '-p', 'planning.station_table_ports:=false'],
        cwd=ROOT, env=env, stdout=log, stderr=subprocess.STDOUT)
    rclpy.init()
    peer = Peer()
    executor = SingleThreadedExecutor()
    executor.add_node(peer)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    cell = Cell.from_yaml(default_cell_path())
    pairs = station_pairs(cell)[:args.pairs or None]
    candidates = random_pairs(cell, 400)
    far = sorted(candidates, key=lambda p: -float(np.abs(p[0] - p[1]).sum()))[:FAR_JOINTS]
    rng = np.random.default_rng(7)
    load = [os.getloadavg()]
    rows = {'idle': [], 'planning': []}
    try:
        ready_s = _ready(peer)
        status = peer.status()
        print(f'node ready with the station table ({status["station_table"]} pairs) '
              f'{ready_s:.1f} s after discovery; kernels ahead {status["kernels_ahead"]}, '
              f'compiled {status["kernels_compiled"]}', flush=True)
        counter, bad = [0], set()
        # Warm-up (not counted): stops idle and while planning.
        for k in range(3):
            _idle(peer)
            _running(peer, f'warm-i{k}', pairs[0], 0.3, args.lead)
            _stop(peer, f'warm-s{k}', f'warm-i{k}', args.lead)
            _running(peer, f'warm-b{k}', pairs[0], 0.3, args.lead + PLANNING_BEFORE)
            _busy_stop(peer, f'warm-t{k}', f'warm-b{k}', args.lead, far, counter, rng, bad,
                       _again(peer, f'warm-b{k}', pairs[0], 0.3, args.lead))
        for turn in range(args.passes):
            for p, (start, goal) in enumerate(pairs):
                for k in range(1, args.moments + 1):
                    fraction = k / (args.moments + 1)
                    order = ('idle', 'planning') if (k + p + turn) % 2 == 0 else \
                        ('planning', 'idle')
                    for condition in order:
                        stop_id = f's{turn}-{p}-{k}-{condition[0]}'
                        move_id = f'm{turn}-{p}-{k}-{condition[0]}'
                        if condition == 'idle':
                            _idle(peer)
                            cycle = _running(peer, move_id, (start, goal), fraction, args.lead)
                            row = _stop(peer, stop_id, move_id, args.lead)
                        else:
                            cycle = _running(peer, move_id, (start, goal), fraction,
                                             args.lead + PLANNING_BEFORE)
                            row = _busy_stop(peer, stop_id, move_id, args.lead, far, counter,
                                             rng, bad, _again(peer, move_id, (start, goal),
                                                              fraction, args.lead))
                        row.update(key=f'{turn}-{p}-{k}', pair=[start, goal], moment=k,
                                   move_cycle_time=cycle, rest_of_move=cycle - row['at'],
                                   condition=condition)
                        rows[condition].append(row)
            load.append(os.getloadavg())
            print(f'pass {turn + 1}/{args.passes} done', flush=True)
        final_status = peer.status()
    finally:
        executor.shutdown()
        spinner.join(timeout=10)
        peer.destroy_node()
        rclpy.try_shutdown()
        node.terminate()  # SIGTERM: the node closes its recording
        try:
            node.wait(timeout=60)
        except subprocess.TimeoutExpired:
            node.kill()
            node.wait()
        log.close()
    recorded = _recorded_times(str(temp / 'recordings'))
    for condition_rows in rows.values():
        for row in condition_rows:
            _breakdown(row, recorded)
    against_core = _against_core(cell, rows)
    summary, paired = _summarised(rows)
    report = {
        'what': __doc__.split('\n')[1],
        'node': {'params_file': 'config/wafer_planner.yaml',
                 'overrides': {'roadmap.cache_dir': '(fresh temp dir)',
                               'recording.directory': '(temp dir)',
                               'planning.station_table_ports': False},
                 'status_at_end': final_status},
        'passes': args.passes, 'moments': args.moments, 'pairs': len(pairs),
        'jitter_s': JITTER, 'lead_s': args.lead, 'target_p99_ms': TARGET_MS,
        'against_core': against_core, 'summary': summary,
        'paired_planning_minus_idle_ms': paired,
        'machine': {'cpus': os.cpu_count(), 'python': platform.python_version(),
                    'platform': platform.platform(), 'commit': _head_commit(),
                    'loadavg': load},
        'rows': rows}
    _print(summary, paired)
    print("time to rest / the core's stop found for the moment itself: "
          + json.dumps(against_core), flush=True)
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(report, indent=1) + '\n')
    print(f'written {RESULTS} (node log {temp / "node.log"})', file=sys.stderr)
    return 0


def _against_core(cell, rows: dict) -> dict:
    """
    Return each OK stop's time to rest against the core's stop of its moment (the module).

    Adds ``core_cycle_time`` to the rows compared; a move whose cycle time is not the one
    planned here (another curve than the table's) is counted and not compared.
    """
    planner = Planner(cell, load_or_build(cell).roadmap, PlannerSettings(method=WholeCurve))
    # The moves as the node's station table holds them (built in the same order: a pair may
    # be its reverse's curve backwards in time).
    table = build_table(planner)
    moves, ratios, other = {}, {'made_ahead': [], 'found_for_the_moment': []}, 0
    for row in (r for part in rows.values() for r in part):
        if row['code'] != 'OK' or row.get('cycle_time') is None:
            continue
        pair = tuple(row['pair'])
        if pair not in moves:
            moves[pair] = table.answer(planner, *pair)
        move = moves[pair]
        if abs(move.cycle_time - row['move_cycle_time']) > 1e-9:
            other += 1
            continue
        core = planner.stop(move.trajectory, row['at'], 'bench', verified=move.verification)
        row['core_cycle_time'] = core.cycle_time
        kind = 'made_ahead' if row['made_ahead'] else 'found_for_the_moment'
        ratios[kind].append(row['cycle_time'] / core.cycle_time)
    out = {'moves_not_planned_the_same': other}
    for kind, values in ratios.items():
        out[kind] = {'median': float(np.median(values)), 'p90': float(
            np.percentile(values, 90)), 'max': float(np.max(values)),
            'mean': float(np.mean(values)), 'n': len(values)} if values else {}
    return out


def _summarised(rows: dict) -> tuple:
    """Return the summary per condition and the paired differences of a run's rows."""
    counted = {c: [r for r in rs if c == 'idle' or r.get('overlap')] for c, rs in rows.items()}
    summary = {c: _summary(rs) for c, rs in counted.items()}
    busy, planned = rows['planning'], counted['planning']
    summary['planning']['evidence'] = {
        'stops_asked': len(busy), 'counted': len(planned),
        'joint_requests_sent': sum(len(r['failed_attempts']) + bool(r.get('overlap'))
                                   for r in busy),
        'extra_attempts': sum(len(r['failed_attempts']) for r in busy),
        'joint_codes': _count(r['joint_code'] for r in planned),
        'status_plan_after_ms': _stats([r['status_plan_after_ms'] for r in planned]),
        'joint_answered_after_stop_ms': _stats([r['joint_answered_after_stop_ms']
                                                for r in planned]),
        'joint_planning_ms': _stats([r['joint_planning_ms'] for r in planned])}
    return summary, _paired(counted)


def _from_rows(path: str) -> int:
    """Summarise the rows of an earlier run's file again; print; write ``RESULTS``."""
    report = json.loads(Path(path).read_text())
    report['summary'], report['paired_planning_minus_idle_ms'] = _summarised(report['rows'])
    _print(report['summary'], report['paired_planning_minus_idle_ms'])
    RESULTS.write_text(json.dumps(report, indent=1) + '\n')
    print(f'written {RESULTS}', file=sys.stderr)
    return 0


def _count(items) -> dict:
    out = {}
    for item in items:
        out[item] = out.get(item, 0) + 1
    return out


def _paired(counted: dict) -> dict:
    """Return planning - idle, per (pass, pair, moment) asked in both conditions."""
    idle = {r['key']: r for r in counted['idle']}
    out = {}
    for key in ('e2e_ms', 'node_ms', 'stop_ms', 'verify_ms'):
        out[key] = _stats([r[key] - idle[r['key']][key] for r in counted['planning']
                           if r['key'] in idle and r.get(key) is not None
                           and idle[r['key']].get(key) is not None])
    return out


def _print(summary: dict, paired: dict) -> None:
    print(f"{'ms':<26}" + ''.join(f'{c:>34}' for c in ('idle', 'planning')))
    print(f"{'':<26}" + '     p50     p90     p99     max   n' * 2)
    labels = (('e2e_ms', 'end to end'), ('result_ms', '  publish -> ~/result'),
              ('trajectory_ms', '  publish -> trajectory'), ('node_ms', 'node_ms'),
              ('stop_ms', 'stop_ms'), ('verify_ms', 'verify_ms'),
              ('outside_stop_verify_ms', 'e2e - stop - verify'))
    split = summary['idle'].get('split_ms', {})
    labels += tuple((f'split:{part}', f'  {part}') for part in split)
    for key, label in labels:
        line = f'{label:<26}'
        for condition in ('idle', 'planning'):
            if key.startswith('split:'):
                stats = summary[condition].get('split_ms', {}).get(key[6:], {})
            else:
                stats = summary[condition].get(key, {})
            line += ''.join(f'{stats.get(q, float("nan")):8.2f}'
                            for q in ('p50', 'p90', 'p99', 'max')) + f"{stats.get('n', 0):4d}"
        print(line)
    evidence = summary['planning']['evidence']
    p99 = summary['planning']['e2e_ms'].get('p99', float('nan'))
    print(f"planning: {evidence['counted']}/{evidence['stops_asked']} stops with the joint "
          f"request planned throughout ({evidence['extra_attempts']} extra attempts, joint "
          f"codes {evidence['joint_codes']}); end to end p99 {p99:.2f} ms against the target "
          f"{TARGET_MS:.0f} ms: {'met' if p99 <= TARGET_MS else 'not met'}")
    print('planning - idle, same stop: ' + ', '.join(
        f"{k} p50 {v.get('p50', float('nan')):+.2f}" for k, v in paired.items()))
    print(f"codes: idle {summary['idle']['codes']}, planning {summary['planning']['codes']}")
    for condition in ('idle', 'planning'):
        part = summary[condition]
        if 'rest_share_inferred' not in part:
            continue
        by = part['by_timing_inferred']
        print(f"{condition}: 'rest' (inferred: cycle_time = T - at) "
              f"{100 * part['rest_share_inferred']:.1f} %; stop_ms p50 rest "
              f"{by['rest']['stop_ms'].get('p50', float('nan')):.1f} vs braked "
              f"{by['braked']['stop_ms'].get('p50', float('nan')):.1f}; end to end p99 rest "
              f"{by['rest']['e2e_ms'].get('p99', float('nan')):.1f} vs braked "
              f"{by['braked']['e2e_ms'].get('p99', float('nan')):.1f}")
        if part.get('made_ahead_share') is not None:
            source = part['by_source']
            print(f"{condition}: made ahead {100 * part['made_ahead_share']:.1f} %; end to "
                  'end p50 / p99 made ahead ' + '{p50:.1f} / {p99:.1f}'.format(
                      **{'p50': float('nan'), 'p99': float('nan'),
                         **source['made_ahead']['e2e_ms']})
                  + ', found for the moment ' + '{p50:.1f} / {p99:.1f}'.format(
                      **{'p50': float('nan'), 'p99': float('nan'),
                         **source['found_for_the_moment']['e2e_ms']}))


if __name__ == '__main__':
    sys.exit(main())
