"""
Plan one cell's free moves as the node plans a request the station table does not hold.

Run by ``bench_free_moves.py`` in a process of its own, with this checkout's package or an
older commit's first on the path (``PYTHONPATH``), so that both are timed alike. Two modes:

- ``reference``: every station pair and ``N`` random free joint pairs
  (``bench_plan.random_pairs``, seeded by the roadmap seed), unbudgeted with the
  whole-curve optimisation, as long as each takes: the figures the budgeted answers are
  measured against, and each station pair's configurations (its answer's elbow branches);
- ``budgeted``: the same joint pairs, then the station pairs asked as those joint angles,
  then joint angles near them, each through ``PlanningService`` with the packaged
  parameters' budget and a deadline of the packaged ``planning.timeout`` from its start, as
  the node answers them. A version with a library of optima (``Planner.optima``) has the
  station pairs' curves in it first, as the node keeps its station table's.

The reference also plans ``NEAR_EACH`` requests near each station pair (each end's joints
moved by up to ``NEAR`` rad at random, seeded by the roadmap seed): a station re-taught a
little, a pose near a station's.

The first request is planned once before any timing (the kernels and lazy imports). Uses
only what both versions have. Prints one JSON line.

Run: ``python bench/free_moves_runner.py reference|budgeted CELL_FILE SEED N [STATIONS]``
(``STATIONS``: the reference's JSON file, for the station pairs' joint angles).
"""

import json
from pathlib import Path
import sys
import time

from bench_plan import random_pairs  # bench/ is the script's folder, first on sys.path
import numpy as np

from wafer_planner_ros.cell.model import Cell
from wafer_planner_ros.cell.stations import station_pairs
from wafer_planner_ros.errors import PlanningError
from wafer_planner_ros.planner import Planner, PlannerSettings
from wafer_planner_ros.roadmap.cache import load_or_build
from wafer_planner_ros.service.planning import PlanningService
from wafer_planner_ros.service.settings import settings_from
from wafer_planner_ros.trajectory.bspline import CubicBSpline
from wafer_planner_ros.trajectory.methods import WholeCurve


NEAR = 0.1
"""rad: the largest offset, on each joint at each end, of the requests near a station pair."""
NEAR_EACH = 3
"""Requests near each station pair."""


def _timed(plan, curve: bool = False) -> dict:
    """
    Return the answer's cycle time and code, and the planning ms, of ``plan()``.

    ``curve``: with the answer's curve (``describe``) and whether it started from a kept
    optimum (``from_optimum``).
    """
    begun = time.perf_counter()
    try:
        result = plan()
        row = {'duration': result.cycle_time, 'code': 'OK',
               'start_q': result.start_q.tolist(), 'goal_q': result.goal_q.tolist(),
               'from_optimum': bool(result.metrics.get('from_optimum'))}
        if curve:
            row['curve'] = result.trajectory.describe()
    except PlanningError as exc:
        row = {'duration': None, 'code': exc.code.value}
    row['planning_ms'] = (time.perf_counter() - begun) * 1000.0
    return row


def near_pairs(stations: list, seed: int) -> list:
    """Return ``NEAR_EACH`` pairs of joint angles near each answered station pair's ends."""
    rng = np.random.default_rng(seed)
    pairs = []
    for row in stations:
        for _ in range(NEAR_EACH if row['code'] == 'OK' else 0):
            pairs.append([(np.asarray(row[end], float)
                           + rng.uniform(-NEAR, NEAR, 3)).tolist()
                          for end in ('start_q', 'goal_q')])
    return pairs


def main() -> int:
    """Plan and print every move of the mode asked."""
    mode, cell_file, seed, count = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
    cell = Cell.from_yaml(cell_file)
    roadmap = load_or_build(cell, seed=seed).roadmap
    joints = random_pairs(cell, count, seed=seed)
    stations = station_pairs(cell)
    if mode == 'reference':
        planner = Planner(cell, roadmap, PlannerSettings(method='whole-curve'))
        planner.plan(*stations[0])
        rows = {'stations': [dict(_timed(lambda: planner.plan(a, b), curve=True), pair=[a, b])
                             for a, b in stations],
                'joints': [_timed(lambda: planner.plan(a, b)) for a, b in joints]}
        rows['near'] = [dict(_timed(lambda: planner.plan(np.asarray(a), np.asarray(b))),
                             pair=[a, b]) for a, b in near_pairs(rows['stations'], seed)]
    else:
        packaged = settings_from({})
        service = PlanningService(Planner(cell, roadmap), budget=packaged.optimise_budget)

        def answer(a, b):
            return _timed(lambda: service.answer(
                np.asarray(a, float), np.asarray(b, float),
                deadline=time.monotonic() + packaged.timeout))

        answer(*joints[0])
        stored = json.loads(Path(sys.argv[5]).read_text())
        reference = stored['stations']
        library = getattr(service.planner.with_method(WholeCurve), 'optima', None)
        if library is not None:  # as the node's: the station table's curves, kept
            for row in reference:
                if row['code'] == 'OK':
                    library.add(row['start_q'], row['goal_q'],
                                CubicBSpline.described(row['curve']))
        rows = {'joints': [answer(a, b) for a, b in joints],
                'stations': [dict(answer(row['start_q'], row['goal_q']), pair=row['pair'])
                             if row['code'] == 'OK' else {'code': 'skipped', 'pair': row['pair']}
                             for row in reference],
                'near': [answer(*row['pair']) for row in stored.get('near', [])]}
    print(json.dumps({'package': __import__('wafer_planner_ros').__file__, **rows}))
    return 0


if __name__ == '__main__':
    sys.exit(main())
