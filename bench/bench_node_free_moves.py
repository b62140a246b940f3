"""
Benchmark: free moves as the node answers them, on every test cell and roadmap seed.

For the default, pillar and notched cells and roadmap seeds 1-3 (``--cells``, ``--seeds``),
each in a node of its own started cold (an empty cache directory) with the packaged
parameters — ``planning.timeout`` and ``planning.optimise_budget`` as shipped — but for
``cell_file``, ``roadmap.seed``, the cache and recording directories and
``planning.station_table_ports`` (off: the moves through the ports are planned for minutes
after start-up, sharing the cores with what is measured). Once the node is ready and its
station table planned (so that its library of optima holds the table's curves, as a node
in service does), it is asked, one request at a time over DDS on loopback:

1. ``--joints`` random free joint pairs (``bench_plan.random_pairs``, seeded by the roadmap
   seed), each once: its first ask, which no kept answer of its own helps;
2. every station pair asked as the joint angles of its unbudgeted answer.

The cycle times are compared with the same pairs' unbudgeted whole-curve optimisation,
planned in a process of its own (``free_moves_runner.py reference``; ``--references DIR``
keeps and reuses them as ``CELL-SEED-JOINTS.json``), before the node starts; the station
pairs of the default cell also with their optimal-control figures (``bench_free_moves``). Reported
per cell and seed and over all: end to end (request sent to result received) and the
planning time the node reports, median / p99 / max; cycle time over unbudgeted, median /
p90 / worst; every code other than ``OK``. Writes ``bench/results/node_free_moves.json``.

Run: ``python bench/bench_node_free_moves.py [--cells ...] [--seeds ...] [--joints N]
[--references DIR]`` (``make bench`` runs it).
"""

import argparse
import json
import os
from pathlib import Path
import platform
import subprocess
import sys
import tempfile
import threading
import time

from bench_free_moves import CELLS, OPTIMAL_CONTROL, run as run_runner  # bench/ on the path
from bench_node import _status, Peer
import numpy as np
import rclpy
from rclpy.executors import SingleThreadedExecutor
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
RESULTS = HERE / 'results' / 'node_free_moves.json'


def main() -> int:
    """Run the benchmark."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--cells', nargs='+', choices=sorted(CELLS), default=list(CELLS))
    parser.add_argument('--seeds', nargs='+', type=int, default=[1, 2, 3])
    parser.add_argument('--joints', type=int, default=100)
    parser.add_argument('--references', help='a folder keeping the unbudgeted references')
    args = parser.parse_args()
    os.environ.update(ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
                      ROS_DOMAIN_ID=str(100 + os.getpid() % 50))
    references = Path(args.references or tempfile.mkdtemp(prefix='bench_references_'))
    references.mkdir(parents=True, exist_ok=True)
    rclpy.init()
    peer = Peer()
    executor = SingleThreadedExecutor()
    executor.add_node(peer)
    threading.Thread(target=executor.spin, daemon=True).start()
    rows = []
    try:
        for name in args.cells:
            for seed in args.seeds:
                stored = references / f'{name}-{seed}-{args.joints}.json'
                if not stored.exists():
                    stored.write_text(json.dumps(
                        run_runner(ROOT, 'reference', CELLS[name], seed, args.joints)))
                reference = json.loads(stored.read_text())
                got = _in_node(peer, CELLS[name], seed, reference)
                rows += _rows(name, seed, reference, got)
                print(_line(f'{name} seed {seed}', [r for r in rows if r['cell'] == name
                                                    and r['seed'] == seed]), flush=True)
    finally:
        executor.shutdown()
        peer.destroy_node()
        rclpy.try_shutdown()
    figures = {'all': _figures(rows)}
    for name in args.cells:
        figures[name] = _figures([r for r in rows if r['cell'] == name])
    print(_line('all', rows))
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps({
        'machine': {'cpus': os.cpu_count(), 'python': platform.python_version(),
                    'platform': platform.platform()},
        'cells': args.cells, 'seeds': args.seeds, 'joints': args.joints,
        'figures': figures, 'rows': rows}, indent=1) + '\n')
    print(f'written {RESULTS}', file=sys.stderr)
    return 0


def _in_node(peer: Peer, cell_file: Path, seed: int, reference: dict) -> dict:
    """Return the node's answers to the reference's joint pairs, then its station pairs."""
    folder = tempfile.mkdtemp(prefix='bench_node_free_')
    node = subprocess.Popen(
        [sys.executable, '-m', 'wafer_planner_ros.node.main', '--ros-args',
         '-p', f'cell_file:={cell_file}', '-p', f'roadmap.seed:={seed}',
         '-p', 'planning.station_table_ports:=false',
         '-p', f'roadmap.cache_dir:={folder}/cache',
         '-p', f'recording.directory:={folder}/recordings'],
        env=os.environ, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        _wait_ready(peer)
        tag = f'{Path(cell_file).stem}-{seed}-'
        joints = [_ask(peer, f'{tag}j{k}', row['start_q'], row['goal_q'])
                  if row['code'] == 'OK' else None
                  for k, row in enumerate(reference['joints'])]
        stations = [_ask(peer, f'{tag}s{k}', row['start_q'], row['goal_q'])
                    if row['code'] == 'OK' else None
                    for k, row in enumerate(reference['stations'])]
    finally:
        node.terminate()
        node.wait(timeout=60)
    return {'joints': joints, 'stations': stations}


def _wait_ready(peer: Peer) -> None:
    """Wait until the node answers, is ready, and has planned its station table."""
    deadline = time.monotonic() + 600.0
    while True:
        if peer.status.service_is_ready() and peer.joints.get_subscription_count() > 0:
            future = peer.status.call_async(Trigger.Request())
            while not future.done():
                time.sleep(0.001)
            status = json.loads(future.result().message)
            if status['ready'] and status['station_table'] and \
                    status['busy_with'] != 'station_table':
                return
        if time.monotonic() > deadline:
            raise TimeoutError(f'the node was not ready with its table: {_status(peer)}')
        time.sleep(0.1)


def _ask(peer: Peer, request_id: str, start, goal) -> dict:
    """Ask one joint request; return its code, cycle time and times (ms)."""
    msg = JointTrajectory()
    msg.header.frame_id = request_id
    msg.points = [JointTrajectoryPoint(positions=[float(v) for v in start]),
                  JointTrajectoryPoint(positions=[float(v) for v in goal])]
    started = time.perf_counter()
    peer.joints.publish(msg)
    received, values = peer.wait(request_id)
    answer = {'code': values['code'], 'e2e_ms': (received - started) * 1000.0}
    if values['code'] == 'OK':
        answer.update(cycle_time=float(values['cycle_time']),
                      planning_ms=float(values['planning_time_ms']),
                      from_optimum=values.get('from_optimum') == 'True')
    return answer


def _rows(name: str, seed: int, reference: dict, got: dict) -> list:
    """Return the rows of one cell and seed, with their ratios to the references."""
    rows = []
    for kind, refs, answers in (('joint', reference['joints'], got['joints']),
                                ('station', reference['stations'], got['stations'])):
        for ref, answer in zip(refs, answers):
            if answer is None:
                continue  # no unbudgeted answer to compare with (e.g. an end in a port)
            row = dict(answer, cell=name, seed=seed, kind=kind, reference=ref['duration'])
            if answer['code'] == 'OK':
                row['ratio'] = answer['cycle_time'] / ref['duration']
                optimal = OPTIMAL_CONTROL.get(tuple(ref.get('pair', ()))) \
                    if name == 'default' and kind == 'station' else None
                if optimal is not None:
                    row['over_optimal_control'] = answer['cycle_time'] / optimal
            rows.append(row)
    return rows


def _figures(rows: list) -> dict:
    """Return the figures of some rows: by kind, times and ratios."""
    out = {}
    for kind in ('joint', 'station'):
        mine = [r for r in rows if r['kind'] == kind]
        ok = [r for r in mine if r['code'] == 'OK']
        if not mine:
            continue
        codes = {}
        for r in mine:
            if r['code'] != 'OK':
                codes[r['code']] = codes.get(r['code'], 0) + 1
        figures = {'requests': len(mine), 'not_ok': codes,
                   'e2e_ms': _stats([r['e2e_ms'] for r in mine])}
        if ok:
            ratio = np.array([r['ratio'] for r in ok])
            figures.update(
                planning_ms=_stats([r['planning_ms'] for r in ok]),
                over_unbudgeted={'median': float(np.median(ratio)),
                                 'p90': float(np.percentile(ratio, 90)),
                                 'worst': float(ratio.max())},
                from_optimum=sum(r['from_optimum'] for r in ok))
            optimal = [r['over_optimal_control'] for r in ok if 'over_optimal_control' in r]
            if optimal:
                figures['over_optimal_control'] = {'median': float(np.median(optimal)),
                                                   'worst': float(max(optimal))}
        out[kind] = figures
    return out


def _line(label: str, rows: list) -> str:
    """Return one printed line of figures."""
    figures = _figures(rows)
    parts = [f'{label}:']
    for kind in ('joint', 'station'):
        part = figures.get(kind)
        if part is None or 'planning_ms' not in part:
            continue
        e2e, ms, ratio = part['e2e_ms'], part['planning_ms'], part['over_unbudgeted']
        parts.append(
            f"{kind} {part['requests']} (not OK {part['not_ok'] or 0}): end to end median "
            f"{e2e['median']:.0f} ms, p99 {e2e['p99']:.0f}, max {e2e['max']:.0f}; planning "
            f"median {ms['median']:.0f}, p99 {ms['p99']:.0f}; / unbudgeted median "
            f"{ratio['median']:.4f}, p90 {ratio['p90']:.3f}, worst {ratio['worst']:.3f}"
            + (f"; / optimal control worst {part['over_optimal_control']['worst']:.3f}"
               if 'over_optimal_control' in part else ''))
    return '\n  '.join(parts)


def _stats(values) -> dict:
    values = np.asarray(values, float)
    return {'median': float(np.median(values)), 'p99': float(np.percentile(values, 99)),
            'max': float(values.max()), 'n': int(len(values))}


if __name__ == '__main__':
    sys.exit(main())
