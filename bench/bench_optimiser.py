"""
The whole-curve optimisation against an older commit's, in the same run.

For each cell and roadmap seed, every station pair is planned unbudgeted with the
whole-curve optimisation (``optimiser_runner.py``) by this checkout and by commit
``--old`` (default b871dd3, the optimiser before it was made faster), each in a process of
its own, one after the other. The old commit's files are extracted with ``git archive`` into
``~/.cache/wafer_planner_ros/bench/<commit>`` (kept, so that numba's cache of its kernels
is reused: the first run compiles them, about a minute). Per pair: planning ms and cycle
time of both, the speed-up (old ms / new ms) and the cycle-time ratio (new / old); per cell
and seed the medians. Writes ``results/optimiser.json``.

Run: ``python bench/bench_optimiser.py [--seeds 1 2 3] [--cells default pillar notched]
[--old COMMIT]``.
"""

import argparse
import json
import os
from pathlib import Path
import platform
import subprocess
import sys

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
RESULTS = HERE / 'results' / 'optimiser.json'
CELLS = {'default': ROOT / 'config' / 'efem_default.yaml',
         'pillar': ROOT / 'test' / 'support' / 'cells' / 'pillar.yaml',
         'notched': ROOT / 'test' / 'support' / 'cells' / 'notched.yaml'}
OLD = 'b871dd3'


def extracted(commit: str) -> Path:
    """Return the directory holding ``commit``'s files (extracted once)."""
    cache = Path(os.environ.get('XDG_CACHE_HOME') or Path.home() / '.cache')
    where = cache / 'wafer_planner_ros' / 'bench' / commit
    if not (where / 'wafer_planner_ros').is_dir():
        where.mkdir(parents=True, exist_ok=True)
        archive = subprocess.run(['git', '-C', str(ROOT), 'archive', commit],
                                 check=True, capture_output=True).stdout
        subprocess.run(['tar', '-x', '-C', str(where)], input=archive, check=True)
    return where


def run(package_root: Path, cell: Path, seed: int) -> dict:
    """Return the runner's JSON with ``package_root``'s package first on the path."""
    env = dict(os.environ, PYTHONPATH=str(package_root))
    done = subprocess.run([sys.executable, str(HERE / 'optimiser_runner.py'), str(cell),
                           str(seed)], env=env, capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def main() -> int:
    """Run both versions on every cell and seed; print and write the comparison."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--seeds', type=int, nargs='+', default=[1, 2, 3])
    parser.add_argument('--cells', nargs='+', choices=sorted(CELLS), default=list(CELLS))
    parser.add_argument('--old', default=OLD)
    args = parser.parse_args()
    old_root = extracted(args.old)
    runs = []
    for name in args.cells:
        for seed in args.seeds:
            old = run(old_root, CELLS[name], seed)
            new = run(ROOT, CELLS[name], seed)
            rows = []
            print(f'\n{name}, seed {seed}\n{"pair":<24}{"old ms":>9}{"new ms":>9}'
                  f'{"speed-up":>10}{"old s":>8}{"new s":>8}{"new/old":>9}')
            for a, b in zip(old['rows'], new['rows']):
                ratio = None if a['duration'] is None or b['duration'] is None \
                    else b['duration'] / a['duration']
                row = {'from': a['from'], 'to': a['to'], 'old': a, 'new': b,
                       'speed_up': a['planning_ms'] / b['planning_ms'], 'cycle_ratio': ratio}
                rows.append(row)
                print(f"{a['from'] + '->' + a['to']:<24}{a['planning_ms']:>9.0f}"
                      f"{b['planning_ms']:>9.0f}{row['speed_up']:>10.1f}"
                      f"{a['duration'] or float('nan'):>8.3f}"
                      f"{b['duration'] or float('nan'):>8.3f}"
                      f"{ratio or float('nan'):>9.4f}", flush=True)
            ratios = [r['cycle_ratio'] for r in rows if r['cycle_ratio'] is not None]
            old_ms = [r['old']['planning_ms'] for r in rows]
            new_ms = [r['new']['planning_ms'] for r in rows]
            summary = {'median_old_ms': float(np.median(old_ms)),
                       'median_new_ms': float(np.median(new_ms)),
                       'median_speed_up': float(np.median([r['speed_up'] for r in rows])),
                       'speed_up_of_medians': float(np.median(old_ms) / np.median(new_ms)),
                       'cycle_ratio_median': float(np.median(ratios)) if ratios else None,
                       'cycle_ratio_worst': float(max(ratios)) if ratios else None,
                       'cycle_ratio_best': float(min(ratios)) if ratios else None}
            print(f"median planning {summary['median_old_ms']:.0f} -> "
                  f"{summary['median_new_ms']:.0f} ms (x{summary['speed_up_of_medians']:.1f}; "
                  f"median per pair x{summary['median_speed_up']:.1f}); cycle time new/old "
                  f"median {summary['cycle_ratio_median']:.4f}, "
                  f"{summary['cycle_ratio_best']:.4f}..{summary['cycle_ratio_worst']:.4f}",
                  flush=True)
            runs.append({'cell': name, 'seed': seed, 'rows': rows, 'summary': summary})
    RESULTS.parent.mkdir(exist_ok=True)
    RESULTS.write_text(json.dumps({
        'benchmark': f'whole-curve optimisation, unbudgeted: this checkout against {args.old}',
        'machine': {'python': platform.python_version(), 'cpus': os.cpu_count()},
        'old': args.old, 'runs': runs}, indent=1))
    print(f'\nwrote {RESULTS}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
