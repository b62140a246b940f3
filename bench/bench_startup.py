"""
Benchmark: how soon the node answers after its process starts, and how soon it stops.

The node is started as a process (``wafer_planner_node``) with the packaged parameters file
(recording on, into a temporary directory):

1. ``--starts`` times (5) with a warm cache (the roadmap and the station table cached by a
   first start that is not counted; the kernels by the set-up): ``ready``, the node's own
   figure against the process's start time as the kernel recorded it (so it includes the
   interpreter, the re-executed one and every import), and when this script read that line;
   then the first station request and the first joint request, asked at once through
   ``wafer-plan-client``: their code and the node's own receipt-to-answer time
   (``node_ms``); then SIGINT, and how long until the process has ended.
2. A fresh ``roadmap.cache_dir`` (the roadmap built, the table planned after ``ready:``):
   the same two first requests, then SIGTERM while the station table is being planned, and
   how long until the process has ended.
3. The first start after an install: ``wafer-kernels`` into an empty numba cache (its
   time: the compile and the build ahead of time), then a node start on it (ready); the
   same without the build ahead of time (numba's cache only); and a node started on an
   empty numba cache without the set-up's compile: the compile announced, and when it is
   ready.

Prints a table; writes ``bench/results/startup.json``. Usage:
``python bench/bench_startup.py [--starts N]``.
"""

import argparse
import json
import os
from pathlib import Path
import platform
import queue
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / 'bench' / 'results' / 'startup.json'
BIN = Path(sys.executable).parent
READY_LINE = '[wafer_planner]: ready: '
"""The node's readiness line (not 'station table (loaded) ready: ', logged before it)."""
READY = re.compile(r'ready: .*, (\d+\.\d+) s after the process started')
STATION, JOINT = ('loadport1', 'loadlock2'), ('-1.2,2.4,1.3', '1.0,-2.0,-1.0')


class Started:
    """The node as a process, its log read line by line with the time each line was seen."""

    def __init__(self, env: dict, cache: str, recordings: str):
        self.env = env
        self.spawned = time.monotonic()
        self.process = subprocess.Popen(
            [str(BIN / 'wafer_planner_node'), '--ros-args', '--params-file',
             str(ROOT / 'config' / 'wafer_planner.yaml'), '-p', f'roadmap.cache_dir:={cache}',
             # the station pairs only: the moves through the ports would be planned, tens
             # of minutes, beside every start measured
             '-p', 'planning.station_table_ports:=false',
             '-p', f'recording.directory:={recordings}'],
            env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        self.lines = queue.Queue()
        self.log = []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        for line in self.process.stdout:
            self.lines.put((time.monotonic() - self.spawned, line.rstrip()))

    def wait_for(self, text: str, timeout: float) -> tuple:
        """Return (seconds from the spawn, line) of the first line holding ``text``."""
        until = time.monotonic() + timeout
        while time.monotonic() < until:
            try:
                seen, line = self.lines.get(timeout=0.05)
            except queue.Empty:
                continue
            self.log.append(line)
            if text in line:
                return seen, line
        raise RuntimeError(f'no {text!r} within {timeout} s:\n' + '\n'.join(self.log[-20:]))

    def ask(self, start: str, goal: str) -> dict:
        """Ask through wafer-plan-client; return the code, node_ms and the client's time."""
        begun = time.monotonic()
        done = subprocess.run([str(BIN / 'wafer-plan-client'), start, goal, '--raw',
                               '--timeout', '60'], env=self.env, capture_output=True,
                              text=True, timeout=120)
        values = dict(line.strip().split(': ', 1) for line in done.stdout.splitlines()[1:]
                      if line.startswith('  ') and ': ' in line)
        return {'code': values.get('code', done.stdout.strip()[:200]),
                'node_ms': float(values.get('node_ms', 'nan')),
                'client_s': time.monotonic() - begun}

    def stop(self, sig) -> float:
        """Send ``sig``; return the seconds until the process has ended."""
        begun = time.monotonic()
        self.process.send_signal(sig)
        try:
            self.process.wait(timeout=120)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
        return time.monotonic() - begun


def environment(numba_cache: str = '') -> dict:
    """Return the node's environment: DDS on loopback in a domain of this run."""
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
               ROS_DOMAIN_ID=str(30 + os.getpid() % 50), ROS_LOG_DIR=tempfile.mkdtemp(),
               PYTHONUNBUFFERED='1')
    if numba_cache:
        env['NUMBA_CACHE_DIR'] = numba_cache
    return env


def ready_and_first_answers(node: Started, timeout: float) -> dict:
    """Wait for ``ready:``; ask the first station and joint requests; return the figures."""
    seen, line = node.wait_for(READY_LINE, timeout)
    found = {'ready': float(READY.search(line).group(1)), 'seen': seen,
             'kernels': kernels_line(node)}
    found['station'] = node.ask(*STATION)
    found['joint'] = node.ask(*JOINT)
    return found


def kernels_line(node: Started) -> str:
    """Return what the node said of its kernels' load (before ``ready:``)."""
    said = [line for line in node.log if 'planning kernels loaded in' in line]
    return said[-1].split(']: ', 1)[-1] if said else ''


def main() -> int:
    """Run the benchmark; print and store the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--starts', type=int, default=5)
    args = parser.parse_args()
    cache = tempfile.mkdtemp(prefix='bench_startup_cache_')
    recordings = tempfile.mkdtemp(prefix='bench_startup_rec_')
    print('first start: roadmap and station table into an empty cache ...', flush=True)
    first = Started(environment(), cache, recordings)
    first.wait_for('station table (loaded) ready', 900.0)
    first.stop(signal.SIGINT)
    warm = []
    for k in range(args.starts):
        node = Started(environment(), cache, recordings)
        found = ready_and_first_answers(node, 120.0)
        found['exit_after_sigint'] = node.stop(signal.SIGINT)
        warm.append(found)
        print(f"start {k + 1}: ready {found['ready']:.3f} s (seen at {found['seen']:.3f} s); "
              f"first station {found['station']['code']} in {found['station']['node_ms']:.1f}"
              f" ms, first joint {found['joint']['code']} in "
              f"{found['joint']['node_ms']:.1f} ms; exit {found['exit_after_sigint']:.2f} s "
              f"after SIGINT ({found['kernels']})", flush=True)
    fresh = Started(environment(), tempfile.mkdtemp(prefix='bench_startup_fresh_'),
                    recordings)
    cold = ready_and_first_answers(fresh, 300.0)
    fresh.wait_for('station table (loaded): 1/', 300.0)
    cold['exit_after_sigterm_planning_table'] = fresh.stop(signal.SIGTERM)
    print(f"fresh cache directory: ready {cold['ready']:.2f} s; first station "
          f"{cold['station']['code']} in {cold['station']['node_ms']:.1f} ms, first joint "
          f"{cold['joint']['code']} in {cold['joint']['node_ms']:.1f} ms; exit "
          f"{cold['exit_after_sigterm_planning_table']:.2f} s after SIGTERM while the table "
          'was planned', flush=True)
    empty = tempfile.mkdtemp(prefix='bench_startup_numba_')
    begun = time.monotonic()
    subprocess.run([str(BIN / 'wafer-kernels')], env=environment(empty), check=True,
                   capture_output=True)
    install = {'wafer_kernels_s': time.monotonic() - begun}
    node = Started(environment(empty), cache, recordings)
    install['ready_after'] = float(READY.search(node.wait_for(READY_LINE, 120.0)[1]).group(1))
    install['kernels'] = kernels_line(node)
    node.stop(signal.SIGINT)
    # The same without the build ahead of time (another Python, numpy, numba or processor,
    # or edited kernels): numba's cache.
    shutil.rmtree(Path(empty) / 'ahead-of-time')
    node = Started(environment(empty), cache, recordings)
    install['ready_numba_cache'] = float(
        READY.search(node.wait_for(READY_LINE, 120.0)[1]).group(1))
    install['kernels_numba_cache'] = kernels_line(node)
    node.stop(signal.SIGINT)
    node = Started(environment(tempfile.mkdtemp(prefix='bench_startup_numba_')), cache,
                   recordings)
    unset = {'announced': node.wait_for('compiling the planning kernels for this machine',
                                        300.0)[0]}
    unset['ready'] = float(READY.search(node.wait_for(READY_LINE, 600.0)[1]).group(1))
    node.stop(signal.SIGINT)
    print(f"after an install: wafer-kernels {install['wafer_kernels_s']:.1f} s, then ready "
          f"{install['ready_after']:.2f} s ({install['kernels']}); without the build ahead of "
          f"time ready {install['ready_numba_cache']:.2f} s ({install['kernels_numba_cache']})"
          '; without wafer-kernels the node announces the compile at '
          f"{unset['announced']:.1f} s and is ready at {unset['ready']:.1f} s", flush=True)

    def median(values):
        values = sorted(values)
        return values[len(values) // 2]

    results = {
        'machine': {'cpus': os.cpu_count(), 'python': platform.python_version()},
        'starts': warm,
        'ready_median_s': median(s['ready'] for s in warm),
        'seen_median_s': median(s['seen'] for s in warm),
        'first_station_node_ms_median': median(s['station']['node_ms'] for s in warm),
        'first_joint_node_ms_median': median(s['joint']['node_ms'] for s in warm),
        'exit_after_sigint_max_s': max(s['exit_after_sigint'] for s in warm),
        'fresh_cache_dir': cold, 'first_after_install': install,
        'without_the_setup_compile': unset,
    }
    print(f"\nwarm cache, {len(warm)} starts (median): ready {results['ready_median_s']:.3f} "
          's after the process started (target 1.0 s); first station answer '
          f"{results['first_station_node_ms_median']:.1f} ms, first joint answer "
          f"{results['first_joint_node_ms_median']:.1f} ms in the node; exit after SIGINT at "
          f"most {results['exit_after_sigint_max_s']:.2f} s")
    RESULTS.write_text(json.dumps(results, indent=1) + '\n')
    print(f'written {RESULTS}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
