"""
Benchmark: how soon the node is ready after its process starts.

The node is started as a process with the packaged parameters file (recording on, into a
temporary directory) and stopped with SIGINT once its compiled kernels are loaded, ``--starts``
times (5) with a warm cache: the roadmap, the station table and numba's kernels cached by a
first start that is not counted. Each start reports, from the node's log:

- ready: the node's own figure, measured against the process's start time as the kernel
  recorded it (``ready: ... s after the process started``), so it includes the interpreter,
  the re-executed one and every import;
- seen: when this script read that line, from just before it spawned the process;
- table, kernels: when the station table was loaded and the planning kernels loaded (from
  the spawn, as seen): until then station requests wait for the table, and the first
  request of each method loads its kernels itself.

Then one start with an empty numba cache (the first start after an install): whether the
log announces the compile, and how long it takes. Prints a table; writes
``bench/results/startup.json``. Usage: ``python bench/bench_startup.py [--starts N]``.
"""

import argparse
import json
import os
from pathlib import Path
import platform
import re
import signal
import subprocess
import sys
import tempfile
import time

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / 'bench' / 'results' / 'startup.json'
READY = re.compile(r'ready: .*, (\d+\.\d+) s after the process started')
MARKS = {'table': ('station table ready',),
         'kernels': ('planning kernels loaded', 'planning kernels compiled:'),
         'announced': ('compiling the planning kernels for this machine',)}


def start(cache: str, recordings: str, numba_cache: str, timeout: float) -> dict:
    """Start the node once, read its log until its kernels are loaded, stop it."""
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
               ROS_DOMAIN_ID=str(30 + os.getpid() % 50), ROS_LOG_DIR=tempfile.mkdtemp(),
               PYTHONUNBUFFERED='1', NUMBA_CACHE_DIR=numba_cache)
    command = [str(Path(sys.executable).parent / 'wafer_planner_node'), '--ros-args',
               '--params-file', str(ROOT / 'config' / 'wafer_planner.yaml'),
               '-p', f'roadmap.cache_dir:={cache}', '-p', f'recording.directory:={recordings}']
    found, lines = {}, []
    spawned = time.monotonic()
    process = subprocess.Popen(command, env=env, stdout=subprocess.PIPE,
                               stderr=subprocess.STDOUT, text=True)
    try:
        for line in process.stdout:
            seen = time.monotonic() - spawned
            lines.append(line.rstrip())
            match = READY.search(line)
            if match and 'ready' not in found:
                found['ready'], found['seen'] = float(match.group(1)), seen
            for key, marks in MARKS.items():
                if key not in found and any(mark in line for mark in marks):
                    found[key] = seen
            if 'kernels' in found or seen > timeout:
                break
    finally:
        process.send_signal(signal.SIGINT)
        try:
            process.wait(timeout=60)
        except subprocess.TimeoutExpired:
            process.kill()
    if 'ready' not in found:
        raise RuntimeError('the node did not say it was ready:\n' + '\n'.join(lines[-20:]))
    return found


def main() -> int:
    """Run the benchmark; print and store the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--starts', type=int, default=5)
    args = parser.parse_args()
    cache = tempfile.mkdtemp(prefix='bench_startup_cache_')
    recordings = tempfile.mkdtemp(prefix='bench_startup_rec_')
    numba_cache = str(Path(cache) / 'numba')
    print('first start: roadmap, station table and kernels into an empty cache ...',
          flush=True)
    start(cache, recordings, numba_cache, 600.0)
    warm = []
    for k in range(args.starts):
        warm.append(start(cache, recordings, numba_cache, 120.0))
        print(f'start {k + 1}: ready {warm[-1]["ready"]:.3f} s (seen at '
              f'{warm[-1]["seen"]:.3f} s), table {warm[-1].get("table", float("nan")):.3f} s, '
              f'kernels {warm[-1].get("kernels", float("nan")):.3f} s', flush=True)
    first = start(cache, recordings, tempfile.mkdtemp(prefix='bench_startup_numba_'),
                  600.0)

    def median(key):
        values = sorted(s[key] for s in warm if key in s)
        return values[len(values) // 2] if values else None

    results = {
        'machine': {'cpus': os.cpu_count(), 'python': platform.python_version()},
        'starts': warm,
        'ready_median_s': median('ready'), 'seen_median_s': median('seen'),
        'table_median_s': median('table'), 'kernels_median_s': median('kernels'),
        'first_after_install': first,
    }
    print(f'\nwarm cache, {len(warm)} starts (median): ready {results["ready_median_s"]:.3f} s '
          f'after the process started (target 0.5 s); the station table loaded at '
          f'{results["table_median_s"]:.3f} s, the kernels at '
          f'{results["kernels_median_s"]:.3f} s')
    print(f'first start after an install: ready {first["ready"]:.3f} s, compile announced: '
          f'{"announced" in first} (at {first.get("announced", float("nan")):.1f} s), '
          f'kernels compiled by {first.get("kernels", float("nan")):.1f} s')
    RESULTS.write_text(json.dumps(results, indent=1) + '\n')
    print(f'written {RESULTS}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
