"""
The station table at a cold start: planned whole, and again after a station is re-taught.

For the default cell and a cell with 4 loadports and 3 loadlocks (the default enclosure and
robot, stations spread along both walls), roadmap seeds 0 (the node's default) to 2: the
roadmap loaded from (or built into) a temporary cache first, and the kernels compiled, as
after ``make run``; then the whole table planned by the node's planner (whole-curve), each
pair verified; then one loadport moved by 30 mm (a re-teach) and the table built again in
the same cache: the pairs of the unchanged stations inherited (each verified), the others
planned. Wall time of each, pairs planned and inherited. Writes ``results/table.json``.

Run: ``python bench/bench_table.py [--seeds 0 1 2]``.
"""

import argparse
import json
import os
from pathlib import Path
import platform
import re
import sys
import tempfile
import time

import numpy as np

from wafer_planner_ros.cell.model import Cell, default_cell_path
from wafer_planner_ros.cell.stations import station_pairs
from wafer_planner_ros.planner import Planner, PlannerSettings
from wafer_planner_ros.roadmap.cache import load_or_build
from wafer_planner_ros.service.table import build_and_store_table

HERE = Path(__file__).resolve().parent
RESULTS = HERE / 'results' / 'table.json'
FOUR_BY_THREE = {'loadport1': -0.6, 'loadport2': -0.2, 'loadport3': 0.2, 'loadport4': 0.6,
                 'loadlock1': -0.5, 'loadlock2': 0.0, 'loadlock3': 0.5}
"""x (m) of each station of the 4 x 3 cell; loadports at y = 0.26, loadlocks at -0.26."""
MOVED = 0.03
"""m: how far the re-taught loadport moves along the wall."""


def cell_texts() -> dict:
    """Return the cell files' texts: the default cell and the 4 x 3 one."""
    text = default_cell_path().read_text()
    head = text[:text.index('stations:')]
    lines = [f"  {name}: {{wafer_center: [{x}, {0.26 if 'port' in name else -0.26}], "
             f"heading: {1.5708 if 'port' in name else -1.5708}}}"
             for name, x in FOUR_BY_THREE.items()]
    wide = head.replace('name: efem-3lp-2ll', 'name: efem-4lp-3ll') + 'stations:\n' + \
        '\n'.join(lines) + '\n'
    return {'default': text, '4x3': wide}


def retaught(text: str) -> str:
    """Return the cell text with loadport2 moved by ``MOVED`` along the wall."""
    def moved(match):
        return f'loadport2: {{wafer_center: [{float(match.group(1)) + MOVED:g}, '

    return re.sub(r'loadport2: \{wafer_center: \[([-0-9.]+), ', moved, text, count=1)


def timed_table(text: str, folder: Path, name: str, seed: int, cache: Path) -> dict:
    """Return the table of a cell text built in ``cache``: seconds, pairs planned."""
    path = folder / f'{name}.yaml'
    path.write_text(text)
    cell = Cell.from_yaml(path)
    planner = Planner(cell, load_or_build(cell, seed=seed, cache_dir=cache).roadmap,
                      PlannerSettings(method='whole-curve'))
    planned = []
    plan = planner.plan
    planner.plan = lambda *a, **k: planned.append(a[:2]) or plan(*a, **k)
    begun = time.perf_counter()
    table = build_and_store_table(planner, cache)
    seconds = time.perf_counter() - begun
    pairs = len(station_pairs(cell))
    assert len(table.entries) == pairs and not table.failures, table.failures
    return {'seconds': seconds, 'pairs': pairs, 'planned': len(planned),
            'cycle_times': sorted(round(table.answer(planner, *pair).cycle_time, 4)
                                  for pair in station_pairs(cell))}


def main() -> int:
    """Run the benchmark and write the JSON."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--seeds', type=int, nargs='+', default=[0, 1, 2])
    args = parser.parse_args()
    runs = []
    # The kernels compiled and the lazy imports done, as in a node that is ready.
    warm = Cell.from_yaml(default_cell_path())
    Planner(warm, load_or_build(warm).roadmap, PlannerSettings(method='whole-curve')).plan(
        'loadport1', 'loadlock2')
    for name, text in cell_texts().items():
        for seed in args.seeds:
            with tempfile.TemporaryDirectory() as folder:
                folder = Path(folder)
                cache = folder / 'cache'
                whole = timed_table(text, folder, name, seed, cache)
                again = timed_table(retaught(text), folder, name + '-retaught', seed, cache)
            runs.append({'cell': name, 'seed': seed, 'whole': whole, 'retaught': again})
            print(f"{name}, seed {seed}: the whole table ({whole['pairs']} pairs, "
                  f"{whole['planned']} planned, the others reversed) in "
                  f"{whole['seconds']:.2f} s; loadport2 re-taught: {again['planned']} planned "
                  f"in {again['seconds']:.2f} s", flush=True)
    for name in cell_texts():
        whole = [r['whole']['seconds'] for r in runs if r['cell'] == name]
        again = [r['retaught']['seconds'] for r in runs if r['cell'] == name]
        print(f'{name}: whole table median {np.median(whole):.2f} s (max {max(whole):.2f}), '
              f'after a re-teach median {np.median(again):.2f} s (max {max(again):.2f})')
    RESULTS.parent.mkdir(exist_ok=True)
    RESULTS.write_text(json.dumps({
        'benchmark': 'the station table at a cold start, whole and after a re-teach',
        'machine': {'python': platform.python_version(), 'cpus': os.cpu_count()},
        'runs': runs}, indent=1))
    print(f'wrote {RESULTS}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
