"""
Moves from inside one port to inside another, loaded: non-stop against stop-and-go and the limit.

For each test cell (the default one, ``test/cells/*``) and each loadport -> loadlock pair,
roadmap seed 0 (the node's default), planned by the whole-curve optimiser as a
``wafer-plan`` call does, unbudgeted:

- non-stop: ``<loadport>:inside`` -> ``<loadlock>:inside``, one move;
- stop-and-go: the retract (``<loadport>:inside`` -> ``<loadport>``), the transfer
  (``<loadport>`` -> ``<loadlock>``) and the extend (``<loadlock>`` ->
  ``<loadlock>:inside``), each from rest to rest, their cycle times added, on the same
  elbow branch at each station (the fastest such chain);
- the corridor curve of the non-stop move (knot timing alone: it stops at both port
  mouths).

Each answer is verified by the planner (every limit and the port tolerances every
millisecond, the collision proof). Reported per pair: the cycle times, planning time (s),
non-stop / stop-and-go, and on the default cell non-stop / the optimal-control figure of
the same move (direct collocation with IPOPT, every joint and wafer limit including jerk,
the port model of the cell file; computed when ports were specified). Writes
``results/ports.json``.

Run: ``python bench/bench_ports.py``.
"""

import json
import os
from pathlib import Path
import platform
import sys
import time

import numpy as np

from wafer_planner_ros.cell.model import Cell, default_cell_path
from wafer_planner_ros.errors import PlanningError
from wafer_planner_ros.planner import Planner, PlannerSettings
from wafer_planner_ros.roadmap.cache import load_or_build
from wafer_planner_ros.trajectory.methods import KnotTiming, WholeCurve

HERE = Path(__file__).resolve().parent
RESULTS = HERE / 'results' / 'ports.json'
OPTIMAL = {('loadport1', 'loadlock1'): 4.36, ('loadport1', 'loadlock2'): 3.67,
           ('loadport2', 'loadlock1'): 3.86, ('loadport3', 'loadlock2'): 2.80}
"""s: the optimal-control cycle time of the default cell's non-stop loaded moves."""


def _timed(planner, start, goal, branches=None) -> tuple:
    """Return (cycle time or None, planning s, error or None)."""
    began = time.perf_counter()
    try:
        result = planner.plan(start, goal, branches=branches)
    except PlanningError as exc:
        return None, time.perf_counter() - began, f'{exc.code.name}: {exc.message}'
    assert result.verification.ok
    return result.cycle_time, time.perf_counter() - began, None


def pair_row(planner, corridor, loadport, loadlock) -> dict:
    """Return the figures of one pair."""
    inside = (f'{loadport}:inside', f'{loadlock}:inside')
    nonstop, seconds, error = _timed(planner, *inside)
    stop_and_go, legs = None, None
    for ea in [c.elbow for c in planner.cell.stations[loadport].inside]:
        for eb in [c.elbow for c in planner.cell.stations[loadlock].inside]:
            # One elbow branch per station: the retract ends where the transfer starts.
            chain = [_timed(planner, a, b, branches) for a, b, branches in (
                (inside[0], loadport, (ea, ea)), (loadport, loadlock, (ea, eb)),
                (loadlock, inside[1], (eb, eb)))]
            if all(t is not None for t, _, _ in chain) and (
                    stop_and_go is None or sum(t for t, _, _ in chain) < stop_and_go):
                stop_and_go, legs = sum(t for t, _, _ in chain), chain
    row = {'loadport': loadport, 'loadlock': loadlock, 'non_stop': nonstop,
           'planning_s': seconds, 'stop_and_go': stop_and_go,
           'stop_and_go_legs': legs and [t for t, _, _ in legs],
           'corridor_curve': _timed(corridor, *inside)[0], 'error': error}
    if nonstop is not None and stop_and_go is not None:
        row['non_stop_over_stop_and_go'] = nonstop / stop_and_go
    optimal = OPTIMAL.get((loadport, loadlock)) if planner.cell.name == 'efem-3lp-2ll' \
        else None
    if optimal is not None and nonstop is not None:
        row['optimal_control'] = optimal
        row['over_optimal_control'] = nonstop / optimal
    return row


def main() -> int:
    """Plan every cell's pairs and write the results."""
    cells = [default_cell_path()] + sorted((HERE.parent / 'test' / 'cells').glob('*.yaml'))
    report = {}
    for path in cells:
        cell = Cell.from_yaml(path)
        roadmap = load_or_build(cell).roadmap
        planner = Planner(cell, roadmap, PlannerSettings(method=WholeCurve))
        corridor = Planner(cell, roadmap, PlannerSettings(method=KnotTiming))
        pairs = [(a, b) for a in sorted(cell.stations) for b in sorted(cell.stations)
                 if a.startswith('loadport') and b.startswith('loadlock')]
        if path == cells[0]:
            pairs = list(OPTIMAL)
        rows = []
        for loadport, loadlock in pairs:
            row = pair_row(planner, corridor, loadport, loadlock)
            rows.append(row)
            print(f"{cell.name} {loadport} -> {loadlock}: non-stop {row['non_stop']} s "
                  f"(x {row.get('over_optimal_control', float('nan')):.3f} of the limit) in "
                  f"{row['planning_s']:.1f} s; stop-and-go {row['stop_and_go']} s "
                  f"(x {row.get('non_stop_over_stop_and_go', float('nan')):.3f})"
                  + (f"; {row['error']}" if row['error'] else ''), flush=True)
        ratios = [r['over_optimal_control'] for r in rows if 'over_optimal_control' in r]
        report[cell.name] = {
            'pairs': rows,
            'median_over_optimal_control': float(np.median(ratios)) if ratios else None,
            'median_non_stop_over_stop_and_go': float(np.median(
                [r['non_stop_over_stop_and_go'] for r in rows
                 if 'non_stop_over_stop_and_go' in r] or [np.nan])),
            'median_planning_s': float(np.median([r['planning_s'] for r in rows]))}
    RESULTS.parent.mkdir(exist_ok=True)
    RESULTS.write_text(json.dumps({
        'cells': report,
        'machine': {'python': platform.python_version(), 'cpus': os.cpu_count()}},
        indent=1) + '\n')
    print(f'wrote {RESULTS}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
