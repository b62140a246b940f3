"""
Cycle times against the MoveIt-style peer and the physical yardstick, per station pair.

For every station pair of the default cell and both test cells, and every roadmap seed:
the paper's pipeline (``PlannerSettings.paper()``), the corridor pipeline with optimised
knot times (method ``knot-timing``), the whole-curve optimisation (method
``whole-curve``), the same within the node's default ``planning.optimise_budget``, the
peer (``peer.Peer``: OMPL PRM with 1500 milestones, simplification, an interpolating
cubic, TOPP-RA) and the per-axis wafer bound
2 max(sqrt(|dx| / a_x), sqrt(|dy| / a_y)) of the wafer centre's displacement (bang-bang on
each axis, everything else ignored: no motion is faster). Cycle time, planning ms and
peak joint jerk for each; ratios to the peer; and where the whole-curve optimisation's
planning time went, per cell and seed: each stage's share of it (``Planner.plan``'s
``timings_ms``: the drafts are ``spline``) and the timed parts of ``optimise``
(``stopwatch.PARTS``: subproblems, rows, limits, proofs). Then ``--joints`` (100) random
free joint pairs per cell and seed (``bench_plan.random_pairs``, seeded by the roadmap seed):
the whole-curve answer within the node's default budget, the unbudgeted one, the peer, each
one's planning ms and the ratios (budgeted / unbudgeted, budgeted / peer). Writes
``results/cycle.json``.

Run: ``python bench/bench_cycle.py [--seeds 1 2 3] [--cells default pillar notched]
[--joints 100]``.
"""

import argparse
from dataclasses import replace
import json
from pathlib import Path
import platform
import sys
import time

from bench_plan import random_pairs, toppra_time  # bench/: this script's folder is on the path
import numpy as np
from peer import Peer

from wafer_planner_ros.cell.model import Cell, default_cell_path
from wafer_planner_ros.cell.stations import station_pairs
from wafer_planner_ros.errors import PlanningError
from wafer_planner_ros.planner import Planner, PlannerSettings, STAGES
from wafer_planner_ros.roadmap.cache import load_or_build
from wafer_planner_ros.service.settings import settings_from
from wafer_planner_ros.trajectory.stopwatch import PARTS

HERE = Path(__file__).resolve().parent
RESULTS = HERE / 'results' / 'cycle.json'
TEST_CELLS = HERE.parent / 'test' / 'support' / 'cells'
CELLS = {'default': default_cell_path(), 'pillar': TEST_CELLS / 'pillar.yaml',
         'notched': TEST_CELLS / 'notched.yaml'}
OURS = {'paper': PlannerSettings.paper(), 'corridor': PlannerSettings(method='knot-timing'),
        'ours': PlannerSettings(method='whole-curve'),
        'budget': PlannerSettings(method='whole-curve')}
BUDGET = settings_from({}).optimise_budget
"""s: 'budget' is the whole-curve optimisation within the node's default budget (what a
request the station table does not hold gets)."""


def wafer_bound(cell, start: str, goal: str) -> float:
    """Return the per-axis bang-bang time of the wafer centre between two stations (s)."""
    a = np.asarray(cell.stations[start].spec.get('wafer_center') or cell.robot.arm.wafer_center(
        cell.stations[start].configs[0].q))
    b = np.asarray(cell.stations[goal].spec.get('wafer_center') or cell.robot.arm.wafer_center(
        cell.stations[goal].configs[0].q))
    limit = cell.robot.wafer_limit.xy
    return float(2.0 * np.max(np.sqrt(np.abs(b - a) / limit)))


def ours(planner: Planner, start: str, goal: str, reference: bool = False,
         budget=None) -> dict:
    """
    Return our plan's cycle time, planning ms and peak jerk (or its error).

    ``reference``: also TOPP-RA's time-optimal timing of the very same curve; ``budget``:
    seconds of optimisation (``Planner.plan``).
    """
    started = time.perf_counter()
    try:
        result = planner.plan(start, goal, budget=budget)
    except PlanningError as exc:
        return {'duration': None, 'planning_ms': (time.perf_counter() - started) * 1000.0,
                'code': exc.code.value, 'reason': exc.message}
    toppra = toppra_time(planner.cell, result.trajectory) if reference else None
    return {'duration': result.cycle_time, 'planning_ms': result.timings_ms['total'],
            'toppra': toppra, 'toppra_ratio': None if not toppra or not toppra['duration']
            else result.cycle_time / toppra['duration'],
            'peak_jerk': list(result.verification.peak_jerk),
            'jerk_ratio': result.verification.ratios.get('jerk'),
            'certified': result.verification.proof.certified,
            'min_clearance': result.min_clearance, 'warnings': list(result.warnings),
            'stage_ms': {stage: result.timings_ms[stage] for stage in STAGES + PARTS}}


def run(name: str, seed: int, joints: int) -> dict:
    """Return every station pair and ``joints`` random joint pairs of one cell and seed."""
    cell = Cell.from_yaml(CELLS[name])
    roadmap = load_or_build(cell, seed=seed).roadmap
    planners = {key: Planner(cell, roadmap, replace(settings))
                for key, settings in OURS.items()}
    peer = Peer(cell, seed=seed)
    rows = []
    for start, goal in station_pairs(cell):
        row = {'from': start, 'to': goal, 'bound': wafer_bound(cell, start, goal)}
        for key, planner in planners.items():
            row[key] = ours(planner, start, goal, reference=key == 'ours',
                            budget=BUDGET if key == 'budget' else None)
        row['peer'] = peer.plan_stations(start, goal)
        rows.append(row)
        _print_row(row)
    joint_rows = []
    for start, goal in random_pairs(cell, joints, seed=seed):
        row = {'from': start.tolist(), 'to': goal.tolist(),
               'budget': ours(planners['budget'], start, goal, budget=BUDGET),
               'ours': ours(planners['ours'], start, goal), 'peer': peer.plan(start, goal)}
        joint_rows.append(row)
    return {'cell': cell.name, 'seed': seed, 'peer_build_seconds': peer.build_seconds,
            'rows': rows, 'summary': _summary(rows), 'joint_rows': joint_rows,
            'joint_summary': _joint_summary(joint_rows)}


def _ratio(row: dict, key: str):
    mine, peer = row[key]['duration'], row['peer']['duration']
    return None if mine is None or peer is None else mine / peer


def _summary(rows: list) -> dict:
    out = {}
    for key in (*OURS, 'peer'):
        times = [r[key]['duration'] for r in rows if r[key]['duration'] is not None]
        planning = [r[key]['planning_ms'] for r in rows]
        out[key] = {'median_s': float(np.median(times)) if times else None,
                    'median_planning_ms': float(np.median(planning))}
        if key == 'ours':
            toppra = [r[key]['toppra_ratio'] for r in rows if r[key].get('toppra_ratio')]
            out[key]['median_vs_toppra'] = float(np.median(toppra)) if toppra else None
            out[key]['time_share'] = _time_share([r[key] for r in rows])
        if key != 'peer':
            ratios = [x for x in (_ratio(r, key) for r in rows) if x is not None]
            out[key].update(median_vs_peer=float(np.median(ratios)) if ratios else None,
                            worst_vs_peer=float(max(ratios)) if ratios else None,
                            at_most_peer=sum(x <= 1.0 for x in ratios), pairs=len(rows))
    out['bound'] = {'median_s': float(np.median([r['bound'] for r in rows]))}
    return out


def _joint_summary(rows: list) -> dict:
    """Return the random joint pairs' ratios and planning times."""
    def ratios(key, other):
        return [r[key]['duration'] / r[other]['duration'] for r in rows
                if r[key]['duration'] and r[other]['duration']]

    out = {'pairs': len(rows)}
    for key in ('budget', 'ours', 'peer'):
        planning = [r[key]['planning_ms'] for r in rows]
        out[key] = {'median_planning_ms': float(np.median(planning)),
                    'p99_planning_ms': float(np.percentile(planning, 99)),
                    'answered': sum(r[key]['duration'] is not None for r in rows)}
    for name, (key, other) in {'budget_vs_ours': ('budget', 'ours'),
                               'budget_vs_peer': ('budget', 'peer'),
                               'ours_vs_peer': ('ours', 'peer')}.items():
        values = ratios(key, other)
        out[name] = {'median': float(np.median(values)) if values else None,
                     'p90': float(np.percentile(values, 90)) if values else None,
                     'worst': float(max(values)) if values else None}
    return out


def _time_share(planned: list) -> dict:
    """Return where the planning time of these plans went: each stage's share of it all."""
    planned = [p for p in planned if p.get('stage_ms')]
    total = sum(p['planning_ms'] for p in planned)
    return {stage: sum(p['stage_ms'][stage] for p in planned) / total if total else None
            for stage in STAGES + PARTS}


def _print_row(row: dict) -> None:
    cells = [f"{row['from'] + '->' + row['to']:<24}{row['bound']:>7.3f}"]
    for key in (*OURS, 'peer'):
        entry = row[key]
        duration = entry['duration']
        jerk = max(entry.get('peak_jerk') or [float('nan')])
        cells.append(f"{duration if duration is not None else float('nan'):>11.3f}"
                     f"{entry['planning_ms']:>9.0f}{jerk:>8.0f}")
    ratio = _ratio(row, 'ours')
    cells.append(f"{ratio if ratio is not None else float('nan'):>7.3f}")
    print(''.join(cells), flush=True)


def main() -> int:
    """Run the benchmark and write the JSON."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--seeds', type=int, nargs='+', default=[1])
    parser.add_argument('--cells', nargs='+', choices=sorted(CELLS), default=list(CELLS))
    parser.add_argument('--joints', type=int, default=100,
                        help='random free joint pairs per cell and seed (default 100)')
    args = parser.parse_args()
    header = f"{'pair':<24}{'bound':>7}" + ''.join(
        f'{key + " s":>11}{"ms":>9}{"jerk":>8}' for key in (*OURS, 'peer'))
    header += f"{'/peer':>7}"
    runs = []
    for name in args.cells:
        for seed in args.seeds:
            print(f'\n{name}, seed {seed}\n{header}', flush=True)
            result = run(name, seed, args.joints)
            runs.append(result)
            s = result['summary']
            print(f"median: bound {s['bound']['median_s']:.3f} s, " + ', '.join(
                f"{key} {s[key]['median_s']:.3f} s" for key in (*OURS, 'peer'))
                + '; ours/TOPP-RA on our curve '
                f"{s['ours']['median_vs_toppra'] or float('nan'):.3f}"
                + f"; ours/peer median {s['ours']['median_vs_peer']:.3f}, worst "
                f"{s['ours']['worst_vs_peer']:.3f}, at most the peer on "
                f"{s['ours']['at_most_peer']}/{s['ours']['pairs']} pairs")
            share = s['ours']['time_share']
            print('where the planning time of ours went (all pairs): ' + ', '.join(
                f'{stage} {100.0 * share[stage]:.1f} %' for stage in STAGES + PARTS
                if share[stage] is not None), flush=True)
            joint = result['joint_summary']
            print(f"{joint['pairs']} random joint pairs: within the budget / unbudgeted "
                  f"median {joint['budget_vs_ours']['median']:.3f} (p90 "
                  f"{joint['budget_vs_ours']['p90']:.3f}, worst "
                  f"{joint['budget_vs_ours']['worst']:.3f}); within the budget / the peer "
                  f"median {joint['budget_vs_peer']['median']:.3f} (worst "
                  f"{joint['budget_vs_peer']['worst']:.3f}); unbudgeted / the peer median "
                  f"{joint['ours_vs_peer']['median']:.3f}; planning ms median (p99): budget "
                  f"{joint['budget']['median_planning_ms']:.0f} "
                  f"({joint['budget']['p99_planning_ms']:.0f}), unbudgeted "
                  f"{joint['ours']['median_planning_ms']:.0f} "
                  f"({joint['ours']['p99_planning_ms']:.0f}), peer "
                  f"{joint['peer']['median_planning_ms']:.0f} "
                  f"({joint['peer']['p99_planning_ms']:.0f})", flush=True)
    RESULTS.parent.mkdir(exist_ok=True)
    RESULTS.write_text(json.dumps({
        'benchmark': 'cycle times per station pair: ours, the paper, the peer, the bound',
        'machine': {'python': platform.python_version(), 'cpus': __import__('os').cpu_count()},
        'runs': runs}, indent=1))
    print(f'\nwrote {RESULTS}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
