"""
Plan every station pair of one cell with the whole-curve optimisation, unbudgeted; print JSON.

Run by ``bench_optimiser.py`` in a process of its own, once with this checkout's package and
once with an older commit's (``PYTHONPATH``), so that both are timed alike: the first pair
is planned once before the timing (loading the kernels and the lazy imports), then every
pair in turn. Uses only what both versions have.

Run: ``python bench/optimiser_runner.py CELL_FILE SEED``.
"""

import json
import sys
import time

from wafer_planner_ros.cell.model import Cell
from wafer_planner_ros.cell.stations import station_pairs
from wafer_planner_ros.errors import PlanningError
from wafer_planner_ros.planner import Planner, PlannerSettings
from wafer_planner_ros.roadmap.cache import load_or_build


def main() -> int:
    """Plan, time and print every pair."""
    cell = Cell.from_yaml(sys.argv[1])
    roadmap = load_or_build(cell, seed=int(sys.argv[2])).roadmap
    planner = Planner(cell, roadmap, PlannerSettings(method='whole-curve'))
    pairs = station_pairs(cell)
    planner.plan(*pairs[0])
    rows = []
    for start, goal in pairs:
        begun = time.perf_counter()
        try:
            result = planner.plan(start, goal)
            duration, code = result.cycle_time, 'OK'
        except PlanningError as exc:
            duration, code = None, exc.code.value
        rows.append({'from': start, 'to': goal, 'duration': duration, 'code': code,
                     'planning_ms': (time.perf_counter() - begun) * 1000.0})
    print(json.dumps({'package': __import__('wafer_planner_ros').__file__, 'rows': rows}))
    return 0


if __name__ == '__main__':
    sys.exit(main())
