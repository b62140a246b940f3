"""
Whole wafer moves, port to port: non-stop against stop-and-go and the limit, and the cycle.

For each test cell (the default one, ``test/support/cells/*``) and each loadport/loadlock pair,
roadmap seed 0 (the node's default), planned by the whole-curve optimiser as a
``wafer-plan`` call does, unbudgeted, the single-blade swap cycle (``service.cycle``, as
``wafer-plan --cycle``):

- non-stop: ``<loadport>:inside`` -> ``<loadlock>:inside`` loaded, then back empty on the
  same elbow branches;
- stop-and-go: each way the move that stops at both port mouths (``Planner.stop_and_go``),
  loaded, out on its fastest elbow branches and back on those;
- the corridor curve of the non-stop move out (knot timing alone: it stops at both port
  mouths).

Each answer is verified by the planner (every limit of its set and the port tolerances
every millisecond, the collision proof). Reported per pair: the cycle times, each non-stop
move's planning time (s), the way out against its own stop-and-go chain
(``Planner.stop_and_go``: the same move stopping at both port mouths, the cycle's
stop-and-go way out), its time along the channels and on the transfer (shares of its cycle
time), the cycle against the stop-and-go cycle, and on the default cell the way out
against the optimal-control figure of the same move (direct collocation with IPOPT, every
joint and wafer limit including jerk, the port model of the cell file: within its
tolerance band). And the way out as the node answers a request its station table does not
hold (``budgeted``: a new planner, the packaged ``planning.optimise_budget`` and
``planning.timeout``): its planning time and its cycle time against the unbudgeted one's.
The results file written before, if any, is the comparison: each pair's
way out and planning time then (``before_*``). Writes ``results/ports-<cell name>.json``.

Run: ``python bench/bench_ports.py [CELL_FILE ...]`` (default: the three cells), or
``python bench/bench_ports.py CELL_FILE --pair LOADPORT LOADLOCK`` to plan one pair again and
replace its row (and the medians) in the cell's results file.
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
from wafer_planner_ros.service.cycle import loadport_loadlock_pairs, swap_cycle
from wafer_planner_ros.service.settings import settings_from
from wafer_planner_ros.trajectory.methods import KnotTiming, WholeCurve

HERE = Path(__file__).resolve().parent
RESULTS = HERE / 'results'
"""One file per cell, ``ports-<cell name>.json``: a run of one cell leaves the others'."""
OPTIMAL = {('loadport1', 'loadlock1'): 4.36, ('loadport1', 'loadlock2'): 3.67,
           ('loadport2', 'loadlock1'): 3.86, ('loadport3', 'loadlock2'): 2.80}
"""s: the optimal-control cycle time of the default cell's non-stop loaded moves."""
DEFAULT_CELL = 'efem-3lp-2ll'
PACKAGED = settings_from({})
"""The node's packaged parameters: ``planning.optimise_budget`` and ``planning.timeout``."""


def _timed(planner, start, goal) -> tuple:
    """Return (cycle time or None, planning s, error or None) of an unrestricted plan."""
    began = time.perf_counter()
    try:
        result = planner.plan(start, goal)
    except PlanningError as exc:
        return None, time.perf_counter() - began, f'{exc.code.name}: {exc.message}'
    assert result.verification.ok
    return result.cycle_time, time.perf_counter() - began, None


def budgeted(cell, roadmap, start: str, goal: str, load: str) -> dict:
    """
    Return the way out planned as the node plans a request its table does not hold.

    A new planner (nothing kept from an earlier move: no transfer between the mouths), the
    packaged ``planning.optimise_budget`` and the request's deadline ``planning.timeout``
    from now: its planning time, cycle time and stops, or its error.
    """
    planner = Planner(cell, roadmap, PlannerSettings(method=WholeCurve))
    began = time.perf_counter()
    try:
        result = planner.plan(start, goal, deadline=time.monotonic() + PACKAGED.timeout,
                              budget=PACKAGED.optimise_budget, load=load)
    except PlanningError as exc:
        return {'planning_s': time.perf_counter() - began,
                'error': f'{exc.code.name}: {exc.message}'}
    assert result.verification.ok
    return {'planning_s': time.perf_counter() - began, 'cycle_time': result.cycle_time,
            'stops': result.metrics.get('stops'), 'error': None}


def pair_row(planner, corridor, loadport, loadlock) -> dict:
    """Return the figures of one pair: its swap cycle, each move timed."""
    seconds = {}

    def plan(start, goal, branches, load):
        began = time.perf_counter()
        try:
            result = planner.plan(start, goal, branches=branches, load=load)
        finally:
            seconds[(start, goal, load, branches)] = time.perf_counter() - began
        assert result.verification.ok
        return result

    cycle = swap_cycle(planner, loadport, loadlock, plan)
    row = cycle.row()
    out = cycle.moves[0]
    row['planning_s'] = [seconds[(m.start, m.goal, m.load, None if m.branches == (None, None)
                                  else m.branches)] for m in cycle.moves]
    row['non_stop'] = out.cycle_time
    chain = cycle.stop_and_go_moves
    if out.result is not None and chain:
        own = chain[0].cycle_time
        row['own_stop_and_go'], row['over_own_stop_and_go'] = own, out.cycle_time / own
        row['in_port_share'] = out.result.metrics['in_port_time'] / out.cycle_time
        row['transfer_share'] = out.result.metrics['transfer_time'] / out.cycle_time
        row['mouth_speeds'] = [out.result.metrics['start_mouth_speed'],
                               out.result.metrics['goal_mouth_speed']]
    row['corridor_curve'] = _timed(corridor, out.start, out.goal)[0]
    row['budgeted'] = budgeted(planner.cell, planner.roadmap, out.start, out.goal, out.load)
    if row['budgeted']['error'] is None and out.cycle_time is not None:
        row['budgeted']['over_unbudgeted'] = row['budgeted']['cycle_time'] / out.cycle_time
    if cycle.cycle is not None and cycle.stop_and_go is not None:
        row['cycle_over_stop_and_go'] = cycle.cycle / cycle.stop_and_go
    optimal = OPTIMAL.get((loadport, loadlock)) if planner.cell.name == DEFAULT_CELL \
        else None
    if optimal is not None and out.cycle_time is not None:
        row['optimal_control'] = optimal
        row['over_optimal_control'] = out.cycle_time / optimal
    return row


def main(argv=None) -> int:
    """Plan every cell's pairs (or those of the cell files named) and write the results."""
    named = list(sys.argv[1:] if argv is None else argv)
    only = None
    if '--pair' in named:
        k = named.index('--pair')
        only, named = tuple(named[k + 1:k + 3]), named[:k] + named[k + 3:]
        if len(only) != 2 or len(named) != 1:
            raise SystemExit('usage: bench_ports.py CELL_FILE --pair LOADPORT LOADLOCK')
    cells = [Path(p) for p in named] or [default_cell_path()] + sorted(
        (HERE.parent / 'test' / 'support' / 'cells').glob('*.yaml'))
    for path in cells:
        cell = Cell.from_yaml(path)
        roadmap = load_or_build(cell).roadmap
        planner = Planner(cell, roadmap, PlannerSettings(method=WholeCurve))
        corridor = Planner(cell, roadmap, PlannerSettings(method=KnotTiming))
        # The default cell: the pairs with an optimal-control figure.
        pairs = list(OPTIMAL) if cell.name == DEFAULT_CELL else loadport_loadlock_pairs(cell)
        written = RESULTS / f'ports-{cell.name}.json'
        before = {(r['loadport'], r['loadlock']): r for r in json.loads(
            written.read_text())['pairs']} if written.exists() else {}
        rows = [] if only is None else json.loads(written.read_text())['pairs']
        for loadport, loadlock in pairs:
            if only is not None and (loadport, loadlock) != only:
                continue
            row = pair_row(planner, corridor, loadport, loadlock)
            then = before.get((loadport, loadlock), {})
            for key in ('non_stop', 'cycle'):
                row[f'before_{key}'] = then.get(f'before_{key}', then.get(key)) \
                    if only is not None else then.get(key)
            row['before_planning_s'] = (then.get('planning_s') or [None])[0]
            if only is None:
                rows.append(row)
            else:
                rows = [row if (r['loadport'], r['loadlock']) == only else r for r in rows]
            errors = [m['error'] for m in row['moves'] if m['error']]
            print(f"{cell.name} {loadport} <-> {loadlock}: non-stop out {row['non_stop']} s "
                  f"(x {row.get('over_optimal_control', float('nan')):.3f} of the limit, "
                  f"x {row.get('over_own_stop_and_go', float('nan')):.3f} of its own "
                  f"stop-and-go) in {row['planning_s'][0]:.2f} s "
                  f"(before: {row['before_non_stop']} s in {row['before_planning_s']} s); "
                  f"cycle {row['cycle']} s "
                  f"against stop-and-go {row['stop_and_go']} s "
                  f"(x {row.get('cycle_over_stop_and_go', float('nan')):.3f}); "
                  f"budgeted {row['budgeted'].get('cycle_time')} s in "
                  f"{row['budgeted']['planning_s']:.2f} s"
                  + ''.join(f'; {e}' for e in errors), flush=True)

        def median(key, rows=rows):
            values = [r[key] for r in rows if r.get(key) is not None]
            return float(np.median(values)) if values else None

        report = {
            'cell': cell.name, 'pairs': rows,
            'median_over_optimal_control': median('over_optimal_control'),
            'median_over_own_stop_and_go': median('over_own_stop_and_go'),
            'median_cycle_over_stop_and_go': median('cycle_over_stop_and_go'),
            'median_non_stop_planning_s': float(np.median([r['planning_s'][0] for r in rows])),
            'budgeted': _budgeted_summary(rows),
            'machine': {'python': platform.python_version(), 'cpus': os.cpu_count()}}
        RESULTS.mkdir(exist_ok=True)
        written.write_text(json.dumps(report, indent=1) + '\n')
        print(f'wrote {written}')
    return 0


def _budgeted_summary(rows) -> dict:
    """Return the budgeted ways out's planning time (median, p99, max) and cycle ratios."""
    runs = [r['budgeted'] for r in rows if 'budgeted' in r]
    seconds = [b['planning_s'] for b in runs]
    ratios = [b['over_unbudgeted'] for b in runs if b.get('over_unbudgeted') is not None]
    return {'budget_s': PACKAGED.optimise_budget, 'timeout_s': PACKAGED.timeout,
            'planning_s_median': float(np.median(seconds)) if seconds else None,
            'planning_s_p99': float(np.percentile(seconds, 99)) if seconds else None,
            'planning_s_max': max(seconds, default=None),
            'over_unbudgeted_median': float(np.median(ratios)) if ratios else None,
            'over_unbudgeted_max': max(ratios, default=None),
            'errors': sum(b['error'] is not None for b in runs)}


if __name__ == '__main__':
    sys.exit(main())
