"""
The moves through the ports and the whole station table: how long they take to plan.

For each test cell (the default one, ``test/cells/*``) and each roadmap seed (default 0, 1
and 2; from the roadmap cache), one whole-curve planner per limit set plans what the node's
station table holds, group by group as ``node.serving.build_station_tables`` does after a
first start (``build_table``): the station pairs loaded, then empty, then every
loadport/loadlock pair through the ports (inside one port to inside the other and back),
loaded, then empty; each entry verified. Reported per cell, seed and group: the wall time
(the table's time after ``ready:``), and per move through the ports planned (the way back
is the way out backwards): its planning time, its cycle time, its own stop-and-go chain
(``Planner.stop_and_go``: the same move stopping at both port mouths, planned after the
table, its transfers then known) and the ratio, its time along the channels and on the
transfer (shares of its cycle time), its mouth speeds. Writes ``results/port-table.json``.

Run: ``python bench/bench_port_table.py [--seeds 0 1 2] [CELL_FILE ...]``.
"""

import json
import os
from pathlib import Path
import platform
import sys
import time

import numpy as np

from wafer_planner_ros.cell.limits import EMPTY, LOADED
from wafer_planner_ros.cell.model import Cell, default_cell_path
from wafer_planner_ros.cell.stations import station_pairs
from wafer_planner_ros.planner import Planner, PlannerSettings
from wafer_planner_ros.roadmap.cache import load_or_build
from wafer_planner_ros.roadmap.graph import RoadmapSettings
from wafer_planner_ros.service.table import build_table, port_pairs
from wafer_planner_ros.trajectory.curve import Trajectory

HERE = Path(__file__).resolve().parent
RESULTS = HERE / 'results'


def seed_report(cell, seed: int) -> dict:
    """Return one cell's and seed's figures: the four groups of the table, timed."""
    planner = Planner(cell, load_or_build(cell, RoadmapSettings(), seed).roadmap,
                      PlannerSettings(method='whole-curve'))
    report, tables, times = {'seed': seed}, {}, {}
    began = time.perf_counter()
    for group, load, pairs in (('stations', LOADED, station_pairs(cell)),
                               ('stations', EMPTY, station_pairs(cell)),
                               ('ports', LOADED, port_pairs(cell)),
                               ('ports', EMPTY, port_pairs(cell))):
        seconds = {}

        def progress(done, total, pair, last=[time.perf_counter()]):
            now = time.perf_counter()
            seconds[pair], last[0] = now - last[0], now

        start = time.perf_counter()
        table = build_table(planner.for_load(load), progress, pairs=pairs,
                            donor=tables.get((group, LOADED)) if load == EMPTY else None)
        tables[(group, load)] = table
        report[f'{group}_{load}'] = {'seconds': time.perf_counter() - start,
                                     'after_start': time.perf_counter() - began,
                                     'pairs': len(table.entries),
                                     'failures': {'->'.join(p): why for p, why
                                                  in table.failures.items()}}
        times[load] = seconds
    report['table_s'] = time.perf_counter() - began
    # Then, not timed with the table: each move through the ports against its own
    # stop-and-go chain.
    for load in (LOADED, EMPTY):
        table, seconds = tables[('ports', load)], times[load]
        moves = []
        for (start_name, goal), entry in sorted(table.entries.items()):
            duration = Trajectory.from_description(entry['trajectory']).duration
            metrics = entry['metrics']
            stopping = planner.stop_and_go(start_name, goal, load=load).cycle_time
            moves.append({
                'from': start_name, 'to': goal, 'cycle_time': duration,
                'planning_s': seconds.get(f'{start_name}->{goal}'),
                'reversed': bool(metrics.get('reversed')),
                'adopted': bool(metrics.get('adopted')), 'stops': metrics.get('stops'),
                'own_stop_and_go': stopping, 'over_own_stop_and_go': duration / stopping,
                'in_port_share': metrics.get('in_port_time', 0.0) / duration,
                'transfer_share': metrics.get('transfer_time', duration) / duration,
                'mouth_speeds': [metrics.get('start_mouth_speed'),
                                 metrics.get('goal_mouth_speed')]})
        planned = [m['planning_s'] for m in moves if not m['reversed']]
        report[f'ports_{load}'].update(
            moves=moves, planning_s={'median': float(np.median(planned)),
                                     'max': float(np.max(planned))},
            over_own_stop_and_go={'median': float(np.median(
                [m['over_own_stop_and_go'] for m in moves])), 'max': float(np.max(
                    [m['over_own_stop_and_go'] for m in moves]))})
    return report


def main(argv=None) -> int:
    """Plan every cell's tables (or those of the cell files named) and write the results."""
    named = list(sys.argv[1:] if argv is None else argv)
    seeds = [0, 1, 2]
    if '--seeds' in named:
        k = named.index('--seeds')
        rest = named[k + 1:]
        count = next((i for i, a in enumerate(rest) if not a.isdigit()), len(rest))
        seeds, named = [int(a) for a in rest[:count]], named[:k] + rest[count:]
    cells = [Path(p) for p in named] or [default_cell_path()] + sorted(
        (HERE.parent / 'test' / 'cells').glob('*.yaml'))
    reports = []
    for path in cells:
        cell = Cell.from_yaml(path)
        for seed in seeds:
            row = dict(seed_report(cell, seed), cell=cell.name)
            reports.append(row)
            for load in (LOADED, EMPTY):
                ports = row[f'ports_{load}']
                print(f"{cell.name} seed {seed} {load}: {ports['pairs']} moves through the "
                      f"ports in {ports['seconds']:.1f} s (planned: median "
                      f"{ports['planning_s']['median']:.2f} s, max "
                      f"{ports['planning_s']['max']:.2f} s; / own stop-and-go median "
                      f"{ports['over_own_stop_and_go']['median']:.3f}, max "
                      f"{ports['over_own_stop_and_go']['max']:.3f})", flush=True)
            print(f"{cell.name} seed {seed}: the whole table in {row['table_s']:.1f} s",
                  flush=True)
    planned = [m['planning_s'] for r in reports for load in (LOADED, EMPTY)
               for m in r[f'ports_{load}']['moves'] if not m['reversed']]
    summary = {'moves_planned': len(planned), 'planning_s_median': float(np.median(planned)),
               'planning_s_max': float(np.max(planned))}
    print(f'moves through the ports planned: {len(planned)}, median '
          f"{summary['planning_s_median']:.2f} s, max {summary['planning_s_max']:.2f} s")
    RESULTS.mkdir(exist_ok=True)
    written = RESULTS / 'port-table.json'
    written.write_text(json.dumps({
        'cells': reports, 'summary': summary,
        'machine': {'python': platform.python_version(), 'cpus': os.cpu_count()}},
        indent=1) + '\n')
    print(f'wrote {written}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
