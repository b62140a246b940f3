"""
The station table through the ports, stopping at the port mouths first: how soon it answers.

For each test cell (the default one, ``test/cells/*``), roadmap seed 0 (the node's default,
from the roadmap cache), the node's first pass over the moves through the ports
(``build_table(..., stopping=True)`` with one whole-curve planner per limit set, as
``node.serving.build_station_tables`` runs it): every loadport/loadlock pair, inside one
port to inside the other and back, loaded then empty, each the retract, transfer and
extend joined into one curve that stops where they meet (``Planner.stop_and_go``),
verified. Reported per cell and limit set: the wall time in all and per pair planned (the
way back is the way out backwards), and per entry its cycle time against its three legs one
after the other (``legs_cycle_time``) and, where ``results/ports-<cell>.json`` has the pair,
against the non-stop move out the full plan found. Writes ``results/port-table.json``.

Run: ``python bench/bench_port_table.py [CELL_FILE ...]`` (default: the three cells).
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
from wafer_planner_ros.planner import Planner, PlannerSettings
from wafer_planner_ros.roadmap.cache import load_or_build
from wafer_planner_ros.service.table import build_table, port_pairs
from wafer_planner_ros.trajectory.curve import Trajectory

HERE = Path(__file__).resolve().parent
RESULTS = HERE / 'results'


def non_stop(cell_name: str) -> dict:
    """Return the non-stop moves out of ``results/ports-<cell>.json``: {(from, to): s}."""
    path = RESULTS / f'ports-{cell_name}.json'
    if not path.exists():
        return {}
    rows = json.loads(path.read_text())['pairs']
    return {(f"{r['loadport']}:inside", f"{r['loadlock']}:inside"): r['non_stop']
            for r in rows if r.get('non_stop') is not None}


def cell_report(path: Path) -> dict:
    """Return one cell's figures: each limit set's stopping pass over the port pairs."""
    cell = Cell.from_yaml(path)
    planner = Planner(cell, load_or_build(cell).roadmap, PlannerSettings(method='whole-curve'))
    full = non_stop(cell.name)
    report = {'cell': cell.name}
    for load in (LOADED, EMPTY):
        seconds = {}

        def progress(done, total, pair, last=[time.perf_counter()]):
            now = time.perf_counter()
            seconds[pair], last[0] = now - last[0], now

        begun = time.perf_counter()
        table = build_table(planner.for_load(load), progress, pairs=port_pairs(cell),
                            stopping=True)
        total = time.perf_counter() - begun
        entries = []
        for (start, goal), entry in sorted(table.entries.items()):
            duration = Trajectory.from_description(entry['trajectory']).duration
            legs = entry['metrics'].get('legs_cycle_time')
            row = {'from': start, 'to': goal, 'cycle_time': duration,
                   'stops': entry['metrics'].get('stops'),
                   'adopted': bool(entry['metrics'].get('adopted')),
                   'reversed': bool(entry['metrics'].get('reversed')),
                   'legs_cycle_time': legs,
                   'over_legs': None if not legs else duration / legs,
                   'planning_s': seconds.get(f'{start}->{goal}')}
            if load == LOADED and (start, goal) in full:
                row['non_stop'] = full[(start, goal)]
                row['non_stop_over_stopping'] = full[(start, goal)] / duration
            entries.append(row)
        planned = [r['planning_s'] for r in entries if not r['reversed']]
        ratios = [r['over_legs'] for r in entries if r['over_legs'] is not None]
        report[load] = {'seconds': total, 'pairs': len(table.entries),
                        'failures': {'->'.join(p): why for p, why in table.failures.items()},
                        'planned_s': {'median': float(np.median(planned)),
                                      'max': float(np.max(planned))},
                        'over_legs': {'min': min(ratios), 'max': max(ratios)},
                        'entries': entries}
        print(f'{cell.name} {load}: {len(table.entries)} pairs stopping at the port mouths '
              f'in {total:.1f} s (per pair planned: median {np.median(planned):.1f} s, max '
              f'{np.max(planned):.1f} s); cycle time / its legs {min(ratios):.4f}-'
              f'{max(ratios):.4f}', flush=True)
    return report


def main(argv=None) -> int:
    """Run the stopping pass on every cell (or those named) and write the results."""
    named = sys.argv[1:] if argv is None else argv
    cells = [Path(p) for p in named] or [default_cell_path()] + sorted(
        (HERE.parent / 'test' / 'cells').glob('*.yaml'))
    reports = [cell_report(path) for path in cells]
    RESULTS.mkdir(exist_ok=True)
    written = RESULTS / 'port-table.json'
    written.write_text(json.dumps({
        'cells': reports,
        'machine': {'python': platform.python_version(), 'cpus': os.cpu_count()}},
        indent=1) + '\n')
    print(f'wrote {written}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
