"""
Benchmark: the planning node as a process, asked over DDS on loopback.

0. The station table at a cold start (an empty cache directory): how long after the
   roadmap serves it is planned, before anything is measured; then, in process, how long
   loading it from the cache takes. The node's compiled kernels are the set-up's build
   ahead of time, the in-process ones numba's cache (``wafer-kernels``, which
   ``make bench`` runs first, makes both).
1. End-to-end latency, one request at a time (every directed station pair three times,
   answered from the table, and 200 random free joint requests, optimised within
   ``planning.optimise_budget``): request publish to result receipt, against the planning
   time the node itself reports (the core planner's ``timings_ms['total']``), for each kind
   apart. After a warm-up pass, every request is asked twice with recording on and twice
   off (``~/set_recording``, in turns block by block); what recording costs is the median
   over requests of (on - off) for the same request. A joint request asked again starts
   from its own answer, which the node keeps (``Planner.optima``): the warm-up pass is each
   one's first ask (``first_ask``), its cycle times compared with the unbudgeted
   whole-curve optimisation of the same pairs (in process, after the node has stopped).
2. Mixed load: joint requests back to back (each sent when the one before is answered, so
   the planning thread is always busy) while station requests arrive every 50 ms from
   another publisher: the station requests' end-to-end latency (answered from the table
   by a thread of their own, never behind the joint planning) and every code.
3. A burst of 200 station requests from 4 publishers at once, recording on: every result
   received, none lost or duplicated, how many were BUSY, ``~/get_status`` round trips
   throughout, and every request and result in the recording.
4. The node's resident memory, and its child processes' (the planning process, the stop
   maker if started).
Prints a table; writes ``bench/results/node.json``. Usage: ``make bench`` or
``python bench/bench_node.py [--joints N]``.
"""

import argparse
import gc
import json
import os
from pathlib import Path
import platform
import subprocess
import sys
import tempfile
import threading
import time

from bench_plan import random_pairs  # bench/ is the script's folder, first on sys.path
from diagnostic_msgs.msg import DiagnosticStatus
import numpy as np
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from std_msgs.msg import String
from std_srvs.srv import SetBool, Trigger
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from wafer_planner_ros.cell.model import Cell, default_cell_path
from wafer_planner_ros.cell.stations import station_pairs
from wafer_planner_ros.errors import PlanningError
from wafer_planner_ros.node.qos import RELIABLE
from wafer_planner_ros.planner import Planner, PlannerSettings
from wafer_planner_ros.recording.reading import read
from wafer_planner_ros.roadmap.cache import load_or_build
from wafer_planner_ros.service.table import load_table

RESULTS = Path(__file__).resolve().parent / 'results' / 'node.json'
BURST, PUBLISHERS = 200, 4
BLOCK = 12
"""Requests asked in one go with recording on, then off (or off, then on)."""
MIXED_STATIONS, MIXED_PERIOD = 120, 0.05
"""Station requests of the mixed load, and the seconds between them."""


class Peer(Node):
    """Sends requests and collects every result with its receipt time."""

    def __init__(self):
        """Create the publishers, the result subscription and the status client."""
        super().__init__('bench_peer')
        self.received = {}
        self.duplicates = 0
        self.lock = threading.Lock()
        self.create_subscription(DiagnosticStatus, '/wafer_planner/result', self.on_result,
                                 RELIABLE)
        self.stations = [self.create_publisher(String, '/wafer_planner/plan_station_request',
                                               RELIABLE) for _ in range(PUBLISHERS)]
        self.joints = self.create_publisher(JointTrajectory, '/wafer_planner/plan_request',
                                            RELIABLE)
        self.status = self.create_client(Trigger, '/wafer_planner/get_status')
        self.recording = self.create_client(SetBool, '/wafer_planner/set_recording')

    def set_recording(self, on: bool) -> str:
        """Switch the node's recording on or off; return its answer."""
        future = self.recording.call_async(SetBool.Request(data=on))
        while not future.done():
            time.sleep(0.001)
        if not future.result().success:
            raise RuntimeError(future.result().message)
        return future.result().message

    def on_result(self, msg: DiagnosticStatus) -> None:
        """Keep the first result per id; count any second one."""
        now = time.perf_counter()
        with self.lock:
            if msg.name in self.received:
                self.duplicates += 1
            else:
                self.received[msg.name] = (now, {kv.key: kv.value for kv in msg.values})

    def wait(self, request_id: str, timeout: float = 120.0):
        """Return (receipt time, values) of a result."""
        deadline = time.monotonic() + timeout
        while request_id not in self.received:
            if time.monotonic() > deadline:
                raise TimeoutError(request_id)
            time.sleep(0.0005)
        return self.received[request_id]

    def status_round_trip(self) -> float:
        """Return the ``~/get_status`` round trip (ms)."""
        started = time.perf_counter()
        future = self.status.call_async(Trigger.Request())
        while not future.done():
            time.sleep(0.0002)
        return (time.perf_counter() - started) * 1000.0


def main() -> int:
    """Run the benchmark."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--joints', type=int, default=200, help='random joint requests')
    args = parser.parse_args()
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
               ROS_DOMAIN_ID=str(150 + os.getpid() % 50))
    os.environ.update(ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
                      ROS_DOMAIN_ID=env['ROS_DOMAIN_ID'])
    recordings = tempfile.mkdtemp(prefix='bench_recordings_')
    cache = tempfile.mkdtemp(prefix='bench_cache_')  # a cold start: roadmap and table
    node = subprocess.Popen([sys.executable, '-m', 'wafer_planner_ros.node.main',
                             '--ros-args', '-p', 'planning.timeout:=60.0',
                             '-p', f'planning.max_queue:={BURST + 10}',
                             # the station pairs only: the moves through the ports take
                             # an hour or more to plan, and would share the cores meanwhile
                             '-p', 'planning.station_table_ports:=false',
                             '-p', f'roadmap.cache_dir:={cache}',
                             '-p', f'recording.directory:={recordings}'],
                            env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    rclpy.init()
    peer = Peer()
    executor = SingleThreadedExecutor()
    executor.add_node(peer)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    cell = Cell.from_yaml(default_cell_path())
    joints = random_pairs(cell, args.joints)
    try:
        report = run(peer, cell, joints)
        report['node_memory_mb'] = _memory(node.pid)
        peer.set_recording(False)
        report['burst']['recorded'] = _recorded(report.pop('burst_bag'))
    finally:
        executor.shutdown()
        peer.destroy_node()
        rclpy.try_shutdown()
        node.terminate()
        node.wait(timeout=60)
    report['machine'] = {'cpus': os.cpu_count(), 'python': platform.python_version(),
                         'platform': platform.platform()}
    report['table_load_ms'], report['joint_cycle'] = _in_process(cell, cache, joints,
                                                                 report.pop('joint_cycles'))
    e2e, burst = report['sequential'], report['burst']
    print(f"station table planned {report['station_table_seconds']:.1f} s after the roadmap "
          f"(cold); loaded from the cache in {report['table_load_ms']['median']:.1f} ms "
          f"(median of {report['table_load_ms']['n']})")
    for kind, label in (('station', 'station requests (table)'),
                        ('joint', 'joint requests (budget)')):
        part = e2e[kind]
        print(f"{label}: {part['requests']}, end-to-end median {part['e2e_ms']['median']:.1f} "
              f"ms, p99 {part['e2e_ms']['p99']:.1f}, max {part['e2e_ms']['max']:.1f}")
    first = report['first_ask']
    if first:
        print(f"joint requests, first ask (the warm-up pass): {first['requests']}, end-to-end "
              f"median {first['e2e_ms']['median']:.1f} ms, p99 {first['e2e_ms']['p99']:.1f}, "
              f"max {first['e2e_ms']['max']:.1f}; planner median "
              f"{first['planner_ms']['median']:.1f} ms, p99 {first['planner_ms']['p99']:.1f}")
    cycle = report['joint_cycle']
    print(f"joint requests' cycle time / unbudgeted optimum: median {cycle['median']:.4f}, "
          f"p90 {cycle['p90']:.4f}, max {cycle['max']:.4f} ({cycle['n']} pairs; unbudgeted "
          f"planning median {cycle['unbudgeted_ms']['median']:.0f} ms, p99 "
          f"{cycle['unbudgeted_ms']['p99']:.0f})")
    print(f"sequential: {e2e['requests']} requests, end-to-end median "
          f"{e2e['e2e_ms']['median']:.1f} ms (p99 {e2e['e2e_ms']['p99']:.1f}), planner "
          f"median {e2e['planner_ms']['median']:.1f} ms; overhead median "
          f"{e2e['overhead_ms']['median']:.2f} ms "
          f"(p99 {e2e['overhead_ms']['p99']:.2f}): in the node "
          f"{e2e['in_node_overhead_ms']['median']:.2f}, transport and peer "
          f"{e2e['transport_ms']['median']:.2f}")
    mixed = report['mixed']
    print(f"mixed load: {mixed['station_requests']} station requests every "
          f"{MIXED_PERIOD * 1000:.0f} ms while {mixed['joint_requests_answered']} joint "
          'requests were planned back to back: end-to-end median '
          f"{mixed['station_e2e_ms']['median']:.1f} ms, p99 {mixed['station_e2e_ms']['p99']:.1f}"
          f", max {mixed['station_e2e_ms']['max']:.1f}; codes {mixed['station_codes']} "
          f"(joint {mixed['joint_codes']})")
    print(f"burst: {burst['received']}/{burst['sent']} results ({burst['ok']} ok, "
          f"{burst['busy']} BUSY), {burst['duplicates']} duplicates, in {burst['seconds']:.1f}"
          f" s; get_status {burst['status_ms']['n']} calls: median "
          f"{burst['status_ms']['median']:.2f} ms, max {burst['status_ms']['max']:.2f} ms; "
          f"slowest (ms, s into the burst): {burst['slowest_status']}")
    rec = report['recording']
    print(f"recording on vs off: planner median {rec['on']['planner_ms']['median']:.2f} vs "
          f"{rec['off']['planner_ms']['median']:.2f} ms, "
          f"end-to-end median {rec['on']['e2e_ms']['median']:.2f} vs "
          f"{rec['off']['e2e_ms']['median']:.2f} ms, overhead median "
          f"{rec['on']['overhead_ms']['median']:.2f} vs "
          f"{rec['off']['overhead_ms']['median']:.2f} ms; per request, on - off: "
          f"end-to-end median {rec['paired_e2e_difference_ms']['median']:+.2f} ms, "
          f"overhead median {rec['paired_overhead_difference_ms']['median']:+.2f} ms")
    print(f"burst recorded: {burst['recorded']}")
    print(f"node memory: {report['node_memory_mb']}")
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(report, indent=1) + '\n')
    print(f'written {RESULTS}', file=sys.stderr)
    return 0


def run(peer: Peer, cell, joints) -> dict:
    """Run the sequential and burst parts; return the figures."""
    deadline = time.monotonic() + 120.0
    while True:  # discovery, then the node's readiness
        ready = peer.status.service_is_ready() and peer.joints.get_subscription_count() > 0 \
            and all(p.get_subscription_count() > 0 for p in peer.stations)
        if ready:
            future = peer.status.call_async(Trigger.Request())
            while not future.done():
                time.sleep(0.001)
            if json.loads(future.result().message)['ready']:
                break
        if time.monotonic() > deadline:
            raise TimeoutError('the node did not become ready')
        time.sleep(0.05)
    pairs = station_pairs(cell)
    # The station table: loaded from the cache, or planned after the roadmap serves.
    ready, deadline = time.monotonic(), time.monotonic() + 3600.0
    while True:
        status = _status(peer)
        if status['station_table'] and status['busy_with'] != 'station_table':
            break
        if time.monotonic() > deadline:
            raise TimeoutError('the station table was not ready within an hour')
        time.sleep(0.2)
    table_seconds = time.monotonic() - ready
    requests = [('s', k, a, b) for k, (a, b) in enumerate(pairs * 3)] + \
        [('j', k, a, b) for k, (a, b) in enumerate(joints)]
    warm = _sequential(peer, requests, 'warm-')
    # Recording on and off in turns, block by block, so that drift in the machine's speed
    # falls on both alike; every request is asked twice in each mode.
    passes = {True: [], False: []}
    blocks = [requests[i:i + BLOCK] for i in range(0, len(requests), BLOCK)]
    for turn in range(2):
        for b, block in enumerate(blocks):
            for on in ((True, False) if (b + turn) % 2 == 0 else (False, True)):
                peer.set_recording(on)
                passes[on].append(_sequential(peer, block, f'{turn}-{on}-'))
    on, off = (_merged(passes[mode]) for mode in (True, False))
    sequential = on  # the node as deployed: recording on
    recording = {'on': on, 'off': off, 'asked_in_each_mode': 2, 'block': BLOCK,
                 'paired_e2e_difference_ms': _paired(passes, 'e2e'),
                 'paired_overhead_difference_ms': _paired(passes, 'overhead')}
    mixed = _mixed(peer, pairs, joints)
    burst_bag = peer.set_recording(True).split('recording to ', 1)[1]  # a bag of its own
    # The burst: 4 publishers at once, get_status polled throughout.
    ids = [[f'b{p}-{k}' for k in range(BURST // PUBLISHERS)] for p in range(PUBLISHERS)]
    status_ms, status_at, done = [], [], threading.Event()
    started = time.perf_counter()

    def publish(p: int) -> None:
        for k, request_id in enumerate(ids[p]):
            a, b = pairs[(p + k) % len(pairs)]
            peer.stations[p].publish(String(data=json.dumps(
                {'id': request_id, 'from': a, 'to': b})))

    def poll() -> None:
        while not done.is_set():
            status_ms.append(peer.status_round_trip())
            status_at.append(time.perf_counter() - started)
            time.sleep(0.02)

    gc.collect()
    gc.freeze()  # keep this process's own collector pauses out of the status times
    poller = threading.Thread(target=poll)
    poller.start()
    senders = [threading.Thread(target=publish, args=(p,)) for p in range(PUBLISHERS)]
    for thread in senders:
        thread.start()
    for thread in senders:
        thread.join()
    every = [i for group in ids for i in group]
    for request_id in every:
        peer.wait(request_id, timeout=600.0)
    seconds = time.perf_counter() - started
    time.sleep(1.0)  # a duplicate would arrive now
    done.set()
    poller.join()
    codes = [peer.received[i][1]['code'] for i in every]
    burst = {'sent': len(every), 'received': sum(1 for i in every if i in peer.received),
             'duplicates': peer.duplicates, 'ok': codes.count('OK'),
             'busy': codes.count('BUSY'), 'seconds': seconds,
             'status_ms': _stats(np.array(status_ms)),
             'slowest_status': sorted(([round(ms, 1), round(at, 2)] for ms, at
                                       in zip(status_ms, status_at)), reverse=True)[:5]}
    return {'benchmark': 'wafer_planner_node over DDS on loopback, default cell',
            'station_table_seconds': table_seconds, 'sequential': sequential,
            'joint_cycles': warm['cycle'], 'first_ask': _merged([warm]).get('joint'),
            'recording': recording, 'mixed': mixed, 'burst': burst, 'burst_bag': burst_bag}


def _mixed(peer: Peer, pairs, joints) -> dict:
    """Station requests every ``MIXED_PERIOD`` s while joint requests keep the planner busy."""
    done, joint_codes = threading.Event(), []

    def plan_joints() -> None:
        for k, (a, b) in enumerate(joints * 10):
            if done.is_set():
                return
            msg = JointTrajectory()
            msg.header.frame_id = f'mixed-j{k}'
            msg.points = [JointTrajectoryPoint(positions=a.tolist()),
                          JointTrajectoryPoint(positions=b.tolist())]
            peer.joints.publish(msg)
            joint_codes.append(peer.wait(msg.header.frame_id)[1]['code'])

    planning = threading.Thread(target=plan_joints)
    planning.start()
    time.sleep(0.5)
    sent = {}
    for k in range(MIXED_STATIONS):
        a, b = pairs[k % len(pairs)]
        sent[f'mixed-s{k}'] = time.perf_counter()
        peer.stations[1].publish(String(data=json.dumps({'id': f'mixed-s{k}', 'from': a,
                                                         'to': b})))
        time.sleep(MIXED_PERIOD)
    answers = {i: peer.wait(i) for i in sent}
    done.set()
    planning.join()
    codes = [values['code'] for _, values in answers.values()]
    return {'station_requests': len(sent), 'station_e2e_ms': _stats(np.array(
                [(answers[i][0] - sent[i]) * 1000.0 for i in sent])),
            'station_codes': {c: codes.count(c) for c in sorted(set(codes))},
            'station_sources': sorted({values.get('source', '') for _, values
                                       in answers.values()}),
            'joint_requests_answered': len(joint_codes),
            'joint_codes': {c: joint_codes.count(c) for c in sorted(set(joint_codes))}}


def _status(peer: Peer) -> dict:
    future = peer.status.call_async(Trigger.Request())
    while not future.done():
        time.sleep(0.001)
    return json.loads(future.result().message)


def _sequential(peer: Peer, requests, prefix: str) -> dict:
    """Ask station ('s', k, from, to) and joint ('j', k, start, goal) requests in turn."""
    e2e, planner, in_node, keys, cycle = [], [], [], [], {}

    def ask(request_id: str, send) -> None:
        started = time.perf_counter()
        send()
        received, values = peer.wait(request_id)
        if 'planning_time_ms' in values and values['code'] == 'OK':
            keys.append(request_id[len(prefix):])
            e2e.append((received - started) * 1000.0)
            planner.append(float(values['planning_time_ms']))
            in_node.append(float(values['node_ms']))
            cycle[keys[-1]] = float(values['cycle_time'])
    for kind, k, a, b in requests:
        request_id = f'{prefix}{kind}{k}'
        if kind == 's':
            request = String(data=json.dumps({'id': request_id, 'from': a, 'to': b}))
            ask(request_id, lambda: peer.stations[0].publish(request))
        else:
            msg = JointTrajectory()
            msg.header.frame_id = request_id
            msg.points = [JointTrajectoryPoint(positions=a.tolist()),
                          JointTrajectoryPoint(positions=b.tolist())]
            ask(request_id, lambda: peer.joints.publish(msg))
    return {'e2e': e2e, 'planner': planner, 'in_node': in_node, 'keys': keys, 'cycle': cycle}


def _merged(passes) -> dict:
    """Return the statistics of several passes of ``_sequential``: all, and by kind."""
    out = {}
    for kind in ('all', 's', 'j'):
        chosen = [[kind == 'all' or key.startswith(kind) for key in p['keys']] for p in passes]
        e2e, planner, in_node = (np.concatenate([np.asarray(p[key])[np.asarray(c, bool)]
                                                 for p, c in zip(passes, chosen)])
                                 for key in ('e2e', 'planner', 'in_node'))
        if not len(e2e):
            continue
        stats = {'requests': len(e2e), 'e2e_ms': _stats(e2e), 'planner_ms': _stats(planner),
                 'overhead_ms': _stats(e2e - planner),
                 'in_node_overhead_ms': _stats(in_node - planner),
                 'transport_ms': _stats(e2e - in_node)}
        if kind == 'all':
            out.update(stats)
        else:
            out['station' if kind == 's' else 'joint'] = stats
    return out


def _in_process(cell, cache: str, joints, cycles: dict) -> tuple:
    """
    Return the table's load times and the joint requests' cycle times against the optimum.

    In process, after the node has stopped: ``load_table`` from the node's cache 20 times,
    and the unbudgeted whole-curve optimisation of every joint pair the node answered.
    """
    roadmap = load_or_build(cell, cache_dir=cache).roadmap
    planner = Planner(cell, roadmap, PlannerSettings(method='whole-curve'))
    loads = []
    for _ in range(20):
        loads.append(load_table(planner, cache).seconds * 1000.0)
    ratios, planning = [], []
    for k, (a, b) in enumerate(joints):
        answered = cycles.get(f'j{k}')
        if answered is None:
            continue
        try:
            result = planner.plan(a, b)
        except PlanningError:
            continue
        ratios.append(answered / result.cycle_time)
        planning.append(result.timings_ms['total'])
    ratios = np.array(ratios)
    return _stats(np.array(loads)), dict(
        _stats(ratios), p90=float(np.percentile(ratios, 90)), unbudgeted_ms=_stats(
            np.array(planning)))


def _paired(passes, what: str) -> dict:
    """Return the statistics over requests of (recording on - off), pass by pass."""
    def measure(run) -> dict:
        e2e = np.array(run['e2e'])
        values = e2e if what == 'e2e' else e2e - np.array(run['planner'])
        return dict(zip(run['keys'], values))
    differences = []
    for on, off in zip(passes[True], passes[False]):
        with_on, with_off = measure(on), measure(off)
        differences += [with_on[k] - with_off[k] for k in with_on if k in with_off]
    return _stats(np.array(differences))


def _recorded(bag: str) -> dict:
    """Return what the burst's recording holds, by topic."""
    recording = read(bag)
    return {'complete': recording.complete, 'messages': recording.counts()}


def _memory(pid: int) -> dict:
    """Return the node's VmRSS and VmHWM (MB), and its child processes' by module."""
    fields = _vm(pid)
    children = {}
    for proc in Path('/proc').iterdir():
        try:
            if not proc.name.isdigit() or \
                    int((proc / 'stat').read_text().rsplit(')', 1)[1].split()[1]) != pid:
                continue
            command = (proc / 'cmdline').read_bytes().split(b'\0')
            module = command[command.index(b'-m') + 1].decode().rsplit('.', 1)[-1]
            children[module] = _vm(int(proc.name))
        except (OSError, ValueError, IndexError):
            continue  # ended meanwhile, or not one of the package's
    fields['children'] = children
    fields['VmRSS_with_children'] = round(
        fields['VmRSS'] + sum(child['VmRSS'] for child in children.values()), 1)
    return fields


def _vm(pid: int) -> dict:
    fields = {}
    for line in Path(f'/proc/{pid}/status').read_text().splitlines():
        key, _, value = line.partition(':')
        if key in ('VmRSS', 'VmHWM'):
            fields[key] = round(int(value.split()[0]) / 1024.0, 1)
    return fields


def _stats(values: np.ndarray) -> dict:
    return {'median': float(np.median(values)), 'p99': float(np.percentile(values, 99)),
            'max': float(values.max()), 'n': int(len(values))}


if __name__ == '__main__':
    sys.exit(main())
