"""
Benchmark: roadmap build (cold) and load (from cache) on the default cell.

Each measurement runs in a fresh Python process so that peak memory is its own. Prints a
table and writes ``bench/results/roadmap.json``. Usage: ``make bench`` or
``python bench/bench_roadmap.py [--sizes 1500 5000 15000] [--repeat 3]``.
"""

import argparse
import json
import os
from pathlib import Path
import platform
import statistics
import subprocess
import sys
import tempfile

RESULTS = Path(__file__).resolve().parent / 'results' / 'roadmap.json'

_CHILD = r"""
import json, resource, sys, time
from wafer_planner_ros.cell.model import Cell, default_cell_path
from wafer_planner_ros.roadmap.cache import load_or_build
from wafer_planner_ros.roadmap.graph import RoadmapSettings
cell = Cell.from_yaml(default_cell_path())
settings = RoadmapSettings(nodes=int(sys.argv[1]))
base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
started = time.perf_counter()
result = load_or_build(cell, settings, 0, sys.argv[2])
seconds = time.perf_counter() - started
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
r = result.roadmap
print(json.dumps({'seconds': seconds, 'hit': result.hit, 'nodes': r.node_count,
                  'edges': r.edge_count, 'components': int(r.components.max() + 1),
                  'evaluations': r.stats['clearance_evaluations'],
                  'peak_rss_mb': peak / 1024, 'rss_before_mb': base / 1024,
                  'hash': r.digest}))
"""


def _measure(nodes: int, cache_dir: str) -> dict:
    out = subprocess.run([sys.executable, '-c', _CHILD, str(nodes), cache_dir],
                         capture_output=True, text=True, check=True)
    return json.loads(out.stdout)


def main() -> int:
    """Run the benchmark."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--sizes', type=int, nargs='+', default=[1500, 5000, 15000])
    parser.add_argument('--repeat', type=int, default=3, help='runs per measurement (median)')
    args = parser.parse_args()
    rows = []
    for nodes in args.sizes:
        cold, warm = [], []
        for _ in range(args.repeat):
            with tempfile.TemporaryDirectory() as cache_dir:
                cold.append(_measure(nodes, cache_dir))
                warm.append(_measure(nodes, cache_dir))
        assert not any(c['hit'] for c in cold) and all(w['hit'] for w in warm)
        assert len({c['hash'] for c in cold + warm}) == 1, 'same seed must give one roadmap'
        rows.append({
            'nodes': nodes, 'roadmap_nodes': cold[0]['nodes'], 'edges': cold[0]['edges'],
            'components': cold[0]['components'],
            'clearance_evaluations': cold[0]['evaluations'],
            'build_s': statistics.median(c['seconds'] for c in cold),
            'build_s_all': [c['seconds'] for c in cold],
            'load_s': statistics.median(w['seconds'] for w in warm),
            'load_s_all': [w['seconds'] for w in warm],
            'build_peak_rss_mb': max(c['peak_rss_mb'] for c in cold),
            'build_rss_growth_mb': max(c['peak_rss_mb'] - c['rss_before_mb'] for c in cold),
            'load_peak_rss_mb': max(w['peak_rss_mb'] for w in warm),
        })
        print(f'{nodes} nodes done', file=sys.stderr)
    header = (f"{'nodes':>6} {'edges':>8} {'build s':>8} {'load s':>7} {'build MB':>9} "
              f"{'(+build)':>9} {'load MB':>8}")
    print(header)
    for r in rows:
        print(f"{r['nodes']:>6} {r['edges']:>8} {r['build_s']:>8.2f} {r['load_s']:>7.3f} "
              f"{r['build_peak_rss_mb']:>9.0f} {r['build_rss_growth_mb']:>9.0f} "
              f"{r['load_peak_rss_mb']:>8.0f}")
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps({
        'benchmark': 'roadmap build (cold) and load (cache), default cell, seed 0',
        'machine': {'cpus': os.cpu_count(), 'python': platform.python_version(),
                    'platform': platform.platform()},
        'repeat': args.repeat, 'rows': rows}, indent=2) + '\n')
    print(f'written {RESULTS}', file=sys.stderr)
    return 0


if __name__ == '__main__':
    sys.exit(main())
