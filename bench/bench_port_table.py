"""
The moves through the ports and the whole station table: how long they take to plan.

For each test cell (the default one, ``test/support/cells/*``) and each roadmap seed (default 0, 1
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

Then, as the node does them (``node.serving.build_station_tables`` with a table cache, the
packaged parameters): the whole table of a larger cell, ``cells/efem_4lp3ll.yaml`` (4
loadports, 3 loadlocks; seed 0), and on the default cell (seed 0) a re-taught station:
``RETAUGHT`` moved ``RETEACH_SHIFT`` along x after the whole table was stored, the time to
hold the whole table again (the pairs of the other stations inherited, each verified).

Run: ``python bench/bench_port_table.py [--seeds 0 1 2] [CELL_FILE ...]`` (cell files named:
only those, without the larger cell and the re-teach).
"""

import json
import os
from pathlib import Path
import platform
import sys
import tempfile
import time

import numpy as np

from wafer_planner_ros.cell.limits import EMPTY, LOADED
from wafer_planner_ros.cell.model import Cell, default_cell_path
from wafer_planner_ros.cell.stations import station_pairs
from wafer_planner_ros.node.serving import build_station_tables, table_groups
from wafer_planner_ros.planner import Planner, PlannerSettings
from wafer_planner_ros.roadmap.cache import load_or_build
from wafer_planner_ros.roadmap.graph import RoadmapSettings
from wafer_planner_ros.service.settings import settings_from
from wafer_planner_ros.service.table import build_table, port_pairs
from wafer_planner_ros.trajectory.curve import Trajectory
import yaml  # after the package: ament_flake8 takes wafer_planner_ros for a third party

HERE = Path(__file__).resolve().parent
RESULTS = HERE / 'results'
LARGER = HERE / 'cells' / 'efem_4lp3ll.yaml'
RETAUGHT, RETEACH_SHIFT = 'loadport1', 0.005
"""The station re-taught on the default cell, and by how much along x (m)."""


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


def node_tables(cell, seed: int, cache_dir) -> dict:
    """Plan a cell's whole table as the node does after ``ready:``; return its figures."""
    settings = settings_from({'roadmap.cache_dir': str(cache_dir)})
    planner = Planner(cell, load_or_build(cell, RoadmapSettings(), seed).roadmap)
    planned, began = [], time.perf_counter()

    def publish(load, table):
        planned.append(time.perf_counter() - began)

    build_station_tables(planner, settings, _Quiet(), {}, publish)
    return {'cell': cell.name, 'seed': seed, 'seconds': time.perf_counter() - began,
            'pairs': sum(len(pairs) for _, pairs in table_groups(planner, settings)),
            'longest_pair_s': float(np.max(np.diff([0.0] + planned)))}


def reteach_report(seed: int = 0) -> dict:
    """Return the default cell's whole table's time, then the same after a re-teach."""
    with tempfile.TemporaryDirectory() as cache_dir:
        first = node_tables(Cell.from_yaml(default_cell_path()), seed, cache_dir)
        document = yaml.safe_load(default_cell_path().read_text())
        document['stations'][RETAUGHT]['wafer_center'][0] += RETEACH_SHIFT
        again = node_tables(Cell.from_dict(document), seed, cache_dir)
    return {'station': RETAUGHT, 'shift_m': RETEACH_SHIFT, 'first': first, 'retaught': again}


class _Quiet:
    """A logger that keeps what the node would log to itself."""

    def info(self, text):
        pass

    warning = error = info


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
        (HERE.parent / 'test' / 'support' / 'cells').glob('*.yaml'))
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
    if not named:
        with tempfile.TemporaryDirectory() as cache_dir:
            summary['larger_cell'] = node_tables(Cell.from_yaml(LARGER), 0, cache_dir)
        summary['reteach'] = reteach_report()
        larger, reteach = summary['larger_cell'], summary['reteach']
        print(f"{larger['cell']}: the whole table ({larger['pairs']} pairs) in "
              f"{larger['seconds']:.1f} s (longest pair {larger['longest_pair_s']:.1f} s)")
        print(f"{reteach['station']} re-taught by {reteach['shift_m'] * 1000:.0f} mm: the "
              f"whole table again in {reteach['retaught']['seconds']:.1f} s (longest pair "
              f"{reteach['retaught']['longest_pair_s']:.1f} s; first start "
              f"{reteach['first']['seconds']:.1f} s)")
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
