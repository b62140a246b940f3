"""
Plan one cell's free moves as the node plans a request the station table does not hold.

Run by ``bench_free_moves.py`` in a process of its own, with this checkout's package or an
older commit's first on the path (``PYTHONPATH``), so that both are timed alike. Two modes:

- ``reference``: every station pair and ``N`` random free joint pairs
  (``bench_plan.random_pairs``, seeded by the roadmap seed), unbudgeted with the
  whole-curve optimisation, as long as each takes: the figures the budgeted answers are
  measured against, and each station pair's configurations (its answer's elbow branches);
- ``budgeted``: the same joint pairs, then the station pairs asked as those joint angles,
  each through ``PlanningService`` with the packaged parameters' budget and a deadline of
  the packaged ``planning.timeout`` from its start, as the node answers them.

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


def _timed(plan) -> dict:
    """Return the answer's cycle time and code, and the planning ms, of ``plan()``."""
    begun = time.perf_counter()
    try:
        result = plan()
        row = {'duration': result.cycle_time, 'code': 'OK',
               'start_q': result.start_q.tolist(), 'goal_q': result.goal_q.tolist()}
    except PlanningError as exc:
        row = {'duration': None, 'code': exc.code.value}
    row['planning_ms'] = (time.perf_counter() - begun) * 1000.0
    return row


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
        rows = {'stations': [dict(_timed(lambda: planner.plan(a, b)), pair=[a, b])
                             for a, b in stations],
                'joints': [_timed(lambda: planner.plan(a, b)) for a, b in joints]}
    else:
        packaged = settings_from({})
        service = PlanningService(Planner(cell, roadmap), budget=packaged.optimise_budget)

        def answer(a, b):
            return _timed(lambda: service.answer(
                np.asarray(a, float), np.asarray(b, float),
                deadline=time.monotonic() + packaged.timeout))

        answer(*joints[0])
        reference = json.loads(Path(sys.argv[5]).read_text())['stations']
        rows = {'joints': [answer(a, b) for a, b in joints],
                'stations': [dict(answer(row['start_q'], row['goal_q']), pair=row['pair'])
                             if row['code'] == 'OK' else {'code': 'skipped', 'pair': row['pair']}
                             for row in reference]}
    print(json.dumps({'package': __import__('wafer_planner_ros').__file__, **rows}))
    return 0


if __name__ == '__main__':
    sys.exit(main())
