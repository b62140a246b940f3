"""
Diverted moves: planning time, and cycle time against a move from rest at the same point.

On the default cell (roadmap seed 0, ``load_or_build``), planned by the whole-curve
optimiser unbudgeted against the loaded limit set: every station pair
(``station_pairs``), diverted at ``--moments`` moments evenly spaced strictly inside it
(k T / (moments + 1)) to another station (the next one in the cell file after its goal,
other than its start and goal). Per divert:

- ours: ``Planner.divert(move, at, station)``, verified as every answer is: its cycle time
  (from the moment it leaves the move until it rests at the new station), its method (one
  curve from the moving state, ``blended-divert``, where one is found within
  ``BLEND_SECONDS``, else the controlled stop then the move from where it rests), the
  stop then the move's time either way, and its planning ms;
- the move from rest at the same point: ``Planner.plan(q(at), station)``, as if the robot
  stood still where it was diverted (what a planner that plans from rest alone would be
  asked, a robot it had first stopped abruptly). Ours over it says what leaving a moving
  robot costs.

Reported: ours / from rest (median, p90, max), the stop's share of the stop then the
move, planning ms of ours (median, p99, max) and of the move from rest, how many diverts
are one curve and what those take against the stop then the move. Writes
``bench/results/divert.json`` (every row, the summary, the machine and commit); prints a
table.

With ``--budget S`` each request is planned as the node plans it (``PlanningService`` with
that budget, its deadline ``TIMEOUT`` s after it is asked; no station table), written to
``bench/results/divert_budget.json``.

Run: ``python bench/bench_divert.py [--moments 5] [--moves N] [--budget 0.12]``.
"""

from pathlib import Path
import sys
import time
from typing import Optional

from bench_stop import _stats, arguments, written  # bench/: this folder is on the path

from wafer_planner_ros.cell.model import Cell, default_cell_path
from wafer_planner_ros.cell.stations import station_pairs
from wafer_planner_ros.errors import PlanningError
from wafer_planner_ros.planner import Planner, PlannerSettings
from wafer_planner_ros.planner.stop import BLENDED
from wafer_planner_ros.roadmap.cache import load_or_build
from wafer_planner_ros.service.planning import PlanningService
from wafer_planner_ros.trajectory.methods import WholeCurve

HERE = Path(__file__).resolve().parent
RESULTS = HERE / 'results' / 'divert.json'
BUDGETED = HERE / 'results' / 'divert_budget.json'
TIMEOUT = 2.0
"""s from a request to its deadline with ``--budget``: the node's ``planning.timeout``."""


def elsewhere(cell, start: str, goal: str) -> str:
    """Return the station after ``goal`` in the cell file that is neither end."""
    names = list(cell.stations)
    at = names.index(goal)
    return next(n for n in names[at + 1:] + names[:at] if n not in (start, goal))


def divert_row(planner, move, at: float, station: str, label: str,
               budget: Optional[float] = None) -> dict:
    """
    Return one divert's figures and those of the move from rest at the same point.

    ``budget``: planned as the node plans them (``PlanningService`` with that budget, each
    request's deadline ``TIMEOUT`` s after it is asked); None: unbudgeted.
    """
    row = {'at': at, 'to': station}
    q = move.evaluate([at])[0]
    service = PlanningService(planner, budget=budget)
    try:
        began = time.perf_counter()
        diverted = service.divert(move, at, station, label, _deadline(budget))
        ms = 1e3 * (time.perf_counter() - began)
        began = time.perf_counter()
        from_rest = service.answer(q, station, _deadline(budget))
        rest_ms = 1e3 * (time.perf_counter() - began)
    except PlanningError as exc:
        row.update(error=f'{exc.code.name}: {exc.message}')
        return row
    metrics = diverted.metrics
    row.update(error=None, cycle_time=diverted.cycle_time, method=metrics['divert'],
               stop_time=metrics['stop_time'], onward_time=metrics['onward_time'],
               stop_then_move=metrics['stop_then_move_time'],
               from_rest=from_rest.cycle_time, ratio=diverted.cycle_time / from_rest.cycle_time,
               against_stopping=diverted.cycle_time / metrics['stop_then_move_time'],
               stop_share=metrics['stop_time'] / metrics['stop_then_move_time'], ms=ms,
               timings_ms=dict(diverted.timings_ms), from_rest_ms=rest_ms,
               verified=bool(diverted.verification.ok))
    return row


def _deadline(budget: Optional[float]) -> Optional[float]:
    """Return a request's deadline: ``TIMEOUT`` s from now within a budget, else None."""
    return None if budget is None else time.monotonic() + TIMEOUT


def summary_of(rows) -> dict:
    """Return the summary of some rows."""
    ok = [r for r in rows if r.get('error') is None]
    return {'diverts': len(rows), 'errors': len(rows) - len(ok),
            'ratio': _stats(r['ratio'] for r in ok),
            'stop_share': _stats(r['stop_share'] for r in ok),
            'cycle_time_s': _stats(r['cycle_time'] for r in ok),
            'from_rest_s': _stats(r['from_rest'] for r in ok),
            'ms': _stats((r['ms'] for r in ok), 'p99'),
            'from_rest_ms': _stats((r['from_rest_ms'] for r in ok), 'p99'),
            'methods': sorted({r['method'] for r in ok}),
            'blended': sum(r['method'] == BLENDED for r in ok),
            'blended_against_stopping': _stats(r['against_stopping'] for r in ok
                                               if r['method'] == BLENDED),
            'all_verified': all(r['verified'] for r in ok)}


def _line(name: str, s: dict) -> str:
    if not s['ratio']:
        return f'{name:<30}no divert'
    r, ms, rest = s['ratio'], s['ms'], s['from_rest_ms']
    return (f"{name:<30}{r['median']:>7.3f}{r['p90']:>7.3f}{r['max']:>7.3f}"
            f"{s['stop_share']['median']:>7.2f}{ms['median']:>8.1f}{ms['p99']:>8.1f}"
            f"{ms['max']:>8.1f}{rest['median']:>8.1f}{s['blended']:>6d}{s['errors']:>5d}")


def main() -> int:
    """Run the benchmark."""
    args = arguments(__doc__, 5, budget=True)
    cell = Cell.from_yaml(default_cell_path())
    planner = Planner(cell, load_or_build(cell).roadmap, PlannerSettings(method=WholeCurve))
    warm = planner.plan('loadport2', 'loadlock2')  # warm-up: imports, caches, kernels
    planner.divert(warm.trajectory, 0.5 * warm.trajectory.duration, 'loadlock1', 'warm-up')
    rows, summaries = [], {}
    for start, goal in station_pairs(cell)[:args.moves]:
        name = f'{start}->{goal}'
        move = planner.plan(start, goal).trajectory
        station = elsewhere(cell, start, goal)
        mine = []
        for k in range(1, args.moments + 1):
            at = k * move.duration / (args.moments + 1)
            row = {'from': start, 'goal': goal, 'moment': k, 'duration_of_move': move.duration}
            row.update(divert_row(planner, move, at, station, f'{name} ({k})', args.budget))
            mine.append(row)
        rows += mine
        summaries[f'{name} => {station}'] = summary_of(mine)
        print(_line(f'{name} => {station}', summaries[f'{name} => {station}']),
              file=sys.stderr, flush=True)
    overall = summary_of(rows)
    print(f"{'move => diverted to':<30}{'ratio':>7}{'p90':>7}{'max':>7}{'stop':>7}{'ms':>8}"
          f"{'p99':>8}{'max':>8}{'rest ms':>8}{'blend':>6}{'err':>5}")
    for name, s in list(summaries.items()) + [('[all]', overall)]:
        print(_line(name, s))
    print(f"diverted / from rest at the same point: median {overall['ratio']['median']:.3f}, "
          f"max {overall['ratio']['max']:.3f}; planning median {overall['ms']['median']:.0f} "
          f"ms, p99 {overall['ms']['p99']:.0f} ms; methods {overall['methods']}; every one "
          f"verified: {overall['all_verified']}; errors {overall['errors']}")
    gain = overall['blended_against_stopping']
    if gain:
        print(f"one curve from the moving state in {overall['blended']} of "
              f"{overall['diverts']}: / the stop then the move median {gain['median']:.3f}, "
              f"max {gain['max']:.3f}")
    written(RESULTS if args.budget is None else BUDGETED,
            'diverted moves on the default cell (roadmap seed 0, whole-curve, loaded) against '
            'the move from rest at the same point'
            + ('' if args.budget is None else f', {args.budget} s budget as the node'),
            {'moments_per_move': args.moments, 'budget_s': args.budget, 'summary': overall,
             'moves': summaries, 'rows': rows})
    return 0


if __name__ == '__main__':
    sys.exit(main())
