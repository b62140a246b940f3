"""
Free moves within the node's budget, against an older commit's, in the same run.

A request the station table does not hold (joint angles) gets the whole-curve
optimisation for at most ``planning.optimise_budget`` (the packaged 0.12 s), within the
packaged ``planning.timeout``: how long it takes and how near its answer is to the
unbudgeted optimum. For each cell and roadmap seed (``free_moves_runner.py``, each run in a
process of its own): first the references by this checkout (every station pair and
``--joints`` random free joint pairs, unbudgeted), then the budgeted answers of this
checkout and of commit ``--old`` (default f501ef2: before each sample's clearance was
computed once for all its rows and a kept optimum moved by time), one after the other,
their order alternating from one cell and seed to the next (so that the machine's drift
falls on both alike): the random joint pairs, then the station pairs asked
as the joint angles of their unbudgeted answers, then joint angles near those (each joint
of each end moved by up to 0.1 rad: a station re-taught a little, a pose near a station's).
A version with a library of optima has the station pairs' curves in it first, as the node
keeps its station table's. The old commit's files are
extracted as ``bench_optimiser.py`` does (kept under ``~/.cache``; its kernels compile on
the first run, about a minute, in a warm-up run of each version before any timing).

Figures per version: planning ms (median, p99, max) over every joint request; cycle time /
the unbudgeted optimum of the same pair (median, p90, worst); the station pairs asked as
joint angles against their unbudgeted station answers and, on the default cell, against
the optimal-control figures (``OPTIMAL_CONTROL``). In process, not through the node: the
node's own part of a joint answer (the hand-over to its planning process and back) is
measured by ``bench_node.py`` (a few ms). Writes ``results/free_moves.json``.

Run: ``python bench/bench_free_moves.py [--seeds 1 2 3] [--cells default pillar notched]
[--joints 100] [--old COMMIT] [--references DIR]`` (``--references``: a folder that keeps
the unbudgeted references as ``CELL-SEED-JOINTS.json`` and reuses those it holds, as
``bench_node_free_moves.py`` does: planned by this checkout, they take most of the run).
"""

import argparse
import json
import os
from pathlib import Path
import platform
import subprocess
import sys
import tempfile
from typing import Optional

from bench_optimiser import CELLS, extracted  # bench/ is the script's folder, on sys.path
import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
RESULTS = HERE / 'results' / 'free_moves.json'
OLD = 'f501ef2'
OPTIMAL_CONTROL = {
    ('loadport1', 'loadlock1'): 1.464, ('loadport1', 'loadlock2'): 2.036,
    ('loadport2', 'loadlock1'): 1.567, ('loadport2', 'loadlock2'): 1.568,
    ('loadport3', 'loadlock1'): 2.035, ('loadport3', 'loadlock2'): 1.464,
    ('loadlock1', 'loadport1'): 1.464, ('loadlock2', 'loadport1'): 2.035,
    ('loadlock1', 'loadport2'): 1.567, ('loadlock2', 'loadport2'): 1.567,
    ('loadlock1', 'loadport3'): 2.035, ('loadlock2', 'loadport3'): 1.464}
"""s: the default cell's station pairs solved as optimal control (direct collocation,
piecewise-constant jerk, every limit and the walls), once, outside this repository: no
motion between those poses is faster."""


def run(package_root: Path, *args) -> dict:
    """Return the runner's JSON with ``package_root``'s package first on the path."""
    env = dict(os.environ, PYTHONPATH=str(package_root))
    done = subprocess.run([sys.executable, str(HERE / 'free_moves_runner.py'),
                           *map(str, args)], env=env, capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f'{package_root}: the runner failed:\n{done.stderr[-3000:]}')
    return json.loads(done.stdout.strip().splitlines()[-1])


def summary(rows: list) -> dict:
    """Return the figures of one version's rows (``rows``: the runs' rows, with ratios)."""
    joints = [r for r in rows if r['kind'] == 'joint']
    answered = [r for r in joints if r['ratio'] is not None]
    ms = np.array([r['planning_ms'] for r in joints])
    ratio = np.array([r['ratio'] for r in answered])
    stations = [r for r in rows if r['kind'] == 'station' and r['ratio'] is not None]
    over_oc = [r['over_optimal_control'] for r in stations if 'over_optimal_control' in r]
    return {
        'joint_requests': len(joints), 'joint_failed': len(joints) - len(answered),
        'planning_ms': {'median': float(np.median(ms)), 'p99': float(np.percentile(ms, 99)),
                        'max': float(ms.max())},
        'over_unbudgeted': {'median': float(np.median(ratio)),
                            'p90': float(np.percentile(ratio, 90)),
                            'worst': float(ratio.max())},
        'stations_as_joints_over_unbudgeted': {
            'median': float(np.median([r['ratio'] for r in stations])),
            'worst': float(max(r['ratio'] for r in stations))},
        'stations_as_joints_over_optimal_control': None if not over_oc else {
            'median': float(np.median(over_oc)), 'worst': float(max(over_oc))},
        'stations_as_joints_planning_ms': {
            'median': float(np.median([r['planning_ms'] for r in stations])),
            'max': float(max(r['planning_ms'] for r in stations))},
        'near_stations': _near(rows)}


def _near(rows: list) -> Optional[dict]:
    """Return the figures of the requests near station pairs (None: none answered)."""
    near = [r for r in rows if r['kind'] == 'near']
    answered = [r for r in near if r['ratio'] is not None]
    if not answered:
        return None
    ms = np.array([r['planning_ms'] for r in near])
    ratio = np.array([r['ratio'] for r in answered])
    return {'requests': len(near), 'failed': len(near) - len(answered),
            'from_optimum': sum(bool(r['from_optimum']) for r in answered),
            'planning_ms': {'median': float(np.median(ms)),
                            'p99': float(np.percentile(ms, 99)), 'max': float(ms.max())},
            'over_unbudgeted': {'median': float(np.median(ratio)),
                                'worst': float(ratio.max())}}


def main() -> int:
    """Run the references, then both versions, on every cell and seed; print and write."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--seeds', type=int, nargs='+', default=[1, 2, 3])
    parser.add_argument('--cells', nargs='+', choices=sorted(CELLS), default=list(CELLS))
    parser.add_argument('--joints', type=int, default=100)
    parser.add_argument('--old', default=OLD)
    parser.add_argument('--references', help='a folder keeping the unbudgeted references')
    args = parser.parse_args()
    roots = {'new': ROOT, 'old': extracted(args.old)}
    rows = {'new': [], 'old': []}
    turn = 0
    with tempfile.TemporaryDirectory() as folder:
        # Each version's kernels compiled (or loaded) once, outside the timing.
        warm = run(ROOT, 'reference', CELLS['default'], 1, 1)
        stored = Path(folder) / 'warm-up.json'
        stored.write_text(json.dumps(warm))
        for version in roots:
            run(roots[version], 'budgeted', CELLS['default'], 1, 1, stored)
        for name in args.cells:
            for seed in args.seeds:
                stored = Path(args.references or folder) / \
                    f'{name}-{seed}-{args.joints}.json'
                if stored.exists():
                    reference = json.loads(stored.read_text())
                else:
                    reference = run(ROOT, 'reference', CELLS[name], seed, args.joints)
                    stored.parent.mkdir(parents=True, exist_ok=True)
                    stored.write_text(json.dumps(reference))
                order = ('new', 'old') if turn % 2 == 0 else ('old', 'new')
                turn += 1
                for version in order:
                    got = run(roots[version], 'budgeted', CELLS[name], seed, args.joints,
                              stored)
                    rows[version] += _rows(name, seed, reference, got)
                    mine = [r for r in rows[version] if r['cell'] == name and r['seed'] == seed]
                    ms = [r['planning_ms'] for r in mine if r['kind'] == 'joint']
                    worst = max((r['ratio'] for r in mine if r['ratio'] is not None),
                                default=float('nan'))
                    print(f'{name:8} seed {seed} {version}: joint requests planned in a median '
                          f'{np.median(ms):.0f} ms (p99 {np.percentile(ms, 99):.0f}), worst '
                          f'cycle / unbudgeted {worst:.3f}', flush=True)
    figures = {version: summary(found) for version, found in rows.items()}
    print(f'\n{"":44}{"this checkout":>16}{args.old:>16}')
    lines = (('joint requests: planning ms, median', 'planning_ms', 'median', '.0f'),
             ('joint requests: planning ms, p99', 'planning_ms', 'p99', '.0f'),
             ('joint requests: / unbudgeted, median', 'over_unbudgeted', 'median', '.4f'),
             ('joint requests: / unbudgeted, p90', 'over_unbudgeted', 'p90', '.3f'),
             ('joint requests: / unbudgeted, worst', 'over_unbudgeted', 'worst', '.3f'),
             ('stations as joints: / unbudgeted, worst',
              'stations_as_joints_over_unbudgeted', 'worst', '.3f'),
             ('stations as joints: / optimal control, worst',
              'stations_as_joints_over_optimal_control', 'worst', '.3f'),
             ('stations as joints: planning ms, median',
              'stations_as_joints_planning_ms', 'median', '.0f'))
    for label, group, key, form in lines:
        values = [(figures[v][group] or {}).get(key) for v in ('new', 'old')]
        print(f'{label:44}' + ''.join(f'{"-" if x is None else format(x, form):>16}'
                                      for x in values))
    for label, key, form in (('near stations: planning ms, median', 'median', '.0f'),
                             ('near stations: planning ms, p99', 'p99', '.0f'),
                             ('near stations: / unbudgeted, median', 'median', '.4f'),
                             ('near stations: / unbudgeted, worst', 'worst', '.3f')):
        group = 'planning_ms' if 'ms' in label else 'over_unbudgeted'
        values = [((figures[v]['near_stations'] or {}).get(group) or {}).get(key)
                  for v in ('new', 'old')]
        print(f'{label:44}' + ''.join(f'{"-" if x is None else format(x, form):>16}'
                                      for x in values))
    RESULTS.parent.mkdir(exist_ok=True)
    RESULTS.write_text(json.dumps({
        'machine': platform.platform(), 'cpus': os.cpu_count(), 'old': args.old,
        'seeds': args.seeds, 'cells': args.cells, 'joints': args.joints,
        'figures': figures, 'rows': rows}, indent=1))
    print(f'\nwritten to {RESULTS}')
    return 0


def _rows(name: str, seed: int, reference: dict, got: dict) -> list:
    """Return one version's rows of a cell and seed, with their ratios to the references."""
    rows = []
    for kind, refs, answers in (('joint', reference['joints'], got['joints']),
                                ('station', reference['stations'], got['stations']),
                                ('near', reference['near'], got['near'])):
        for ref, row in zip(refs, answers):
            if ref['code'] != 'OK':
                continue  # not a request that has an answer (e.g. an end inside a port)
            made = {'cell': name, 'seed': seed, 'kind': kind, 'code': row['code'],
                    'planning_ms': row.get('planning_ms'), 'reference': ref['duration'],
                    'from_optimum': row.get('from_optimum', False),
                    'ratio': None if row.get('duration') is None
                    else row['duration'] / ref['duration']}
            if kind == 'station':
                made['pair'] = ref['pair']
                optimal = OPTIMAL_CONTROL.get(tuple(ref['pair'])) if name == 'default' \
                    else None
                if optimal is not None and row.get('duration') is not None:
                    made['over_optimal_control'] = row['duration'] / optimal
            rows.append(made)
    return rows


if __name__ == '__main__':
    sys.exit(main())
