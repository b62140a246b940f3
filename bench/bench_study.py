"""
``wafer-study`` on this machine: the cost of a variant, throughput and parallel efficiency.

Runs the example study (``config/example_study.yaml``: the default cell, 600-node roadmaps,
the node's method, whole-curve; ``--method knot-timing`` for the quick one) with
``random.samples`` added so that it has 12 variants, through the
command-line tool as a user would, once with 1 local worker and once with 2, each into a
fresh directory. Reported: wall time, variants per minute, the parallel efficiency from 1 to
2 workers (t1 / (2 t2)), the median and spread of one variant's cost (its row's
``cost.seconds``), whether both runs gave the same rows (without ``cost``), and what a
1,000-variant study would take on this machine and on 64 cores: at this study's rate (a
third of its variants invalid, so cheap) and with every variant valid (the median valid
variant's cost each). Writes
``results/study.json``.

Run: ``python bench/bench_study.py [--samples N] [--method M]`` (default 6: 12 variants;
the example study's method).
"""

import argparse
import json
import os
from pathlib import Path
import platform
import subprocess
import sys
import tempfile
import time

import numpy as np
from wafer_planner_ros.cell.model import default_cell_path
from wafer_planner_ros.study.results import read_rows, without_cost
import yaml

HERE = Path(__file__).resolve().parent
RESULTS = HERE / 'results'


def run(study: Path, out: Path, workers: int) -> float:
    """Run the study with ``workers`` local workers; return the wall time (s)."""
    started = time.perf_counter()
    done = subprocess.run([sys.executable, '-m', 'wafer_planner_ros.cli.study', str(study),
                           '--out', str(out), '--workers', str(workers)],
                          capture_output=True, text=True)
    seconds = time.perf_counter() - started
    if done.returncode not in (0, 1):
        sys.exit(f'wafer-study failed:\n{done.stderr}')
    return seconds


def main() -> None:
    """Run the benchmark and write results/study.json."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--samples', type=int, default=6)
    parser.add_argument('--method', default=None, help="the study's method (default: the "
                        "example study's)")
    args = parser.parse_args()
    example = default_cell_path().parent / 'example_study.yaml'
    text = yaml.safe_load(example.read_text())
    text['study']['base'] = str(default_cell_path())
    if args.method is not None:
        text['study']['method'] = args.method
    text['study']['random'] = {'samples': args.samples, 'seed': 1}
    folder = Path(tempfile.mkdtemp(prefix='bench_study_'))
    study = folder / 'study.yaml'
    study.write_text(yaml.safe_dump(text))
    times, rows = {}, {}
    for workers in (1, 2):
        times[workers] = run(study, folder / f'out{workers}', workers)
        rows[workers] = read_rows(folder / f'out{workers}')
        print(f'{workers} worker(s): {len(rows[workers])} variants in {times[workers]:.1f} s',
              flush=True)
    count = len(rows[1])
    cost = np.array([r['cost']['seconds'] for r in rows[1] if r['status'] != 'invalid'])
    per_minute = {w: 60.0 * count / t for w, t in times.items()}
    efficiency = times[1] / (2 * times[2])
    seconds_per_variant = times[2] / count * 2  # core-seconds per variant, 2 workers
    figures = {
        'machine': {'cpus': os.cpu_count(), 'python': platform.python_version()},
        'method': text['study']['method'],
        'variants': count,
        'statuses': {s: sum(r['status'] == s for r in rows[1])
                     for s in ('planned', 'incomplete', 'invalid', 'failed')},
        'wall_seconds': {str(w): t for w, t in times.items()},
        'variants_per_minute': {str(w): v for w, v in per_minute.items()},
        'efficiency_1_to_2': efficiency,
        'variant_cost_seconds': {'median': float(np.median(cost)), 'min': float(cost.min()),
                                 'max': float(cost.max())},
        'same_rows': [without_cost(r) for r in rows[1]] == [without_cost(r) for r in rows[2]],
        'thousand_variants_hours': {
            'this machine (2 workers)': 1000 * times[2] / count / 3600,
            '64 cores, same per-core rate': 1000 * seconds_per_variant / 64 / 3600,
            # every variant valid, each costing the median valid one's seconds
            'this machine, all valid': 1000 * float(np.median(cost)) / (2 * efficiency) / 3600,
            '64 cores, all valid': 1000 * float(np.median(cost)) / 64 / 3600},
    }
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / 'study.json').write_text(json.dumps(figures, indent=2) + '\n')
    print(json.dumps(figures, indent=2))


if __name__ == '__main__':
    main()
