"""
A roadmap ready to serve: its planner, when it took over, and how it got there.

The worker's loading thread builds or loads a roadmap (``progress_reporter`` logs the
build), plans once with it (``warm_up``: the compiled kernels load before the first
request), and hands it over as a ``Serving``.
"""

from dataclasses import dataclass

from wafer_planner_ros.errors import PlanningError
from wafer_planner_ros.planner import Planner
from wafer_planner_ros.roadmap.cache import CachedRoadmap


@dataclass(frozen=True)
class Serving:
    """A loaded roadmap and its planner, and when it took over (``time.time_ns()``)."""

    planner: Planner
    cached: CachedRoadmap
    loaded_ns: int


def progress_reporter(logger):
    """Return a roadmap build's progress callback that logs every tenth of the way."""
    last = [-1]

    def report(done: int, total: int, edges: int) -> None:
        tenth = 10 * done // max(total, 1)
        if tenth != last[0]:
            last[0] = tenth
            logger.info(f'building roadmap: {done}/{total} nodes, {edges} edges')
    return report


def warm_up(planner) -> None:
    """Plan once so that the compiled kernels are loaded before the first request."""
    names = sorted(planner.cell.stations)
    try:
        planner.plan(names[0], names[-1])
    except (PlanningError, IndexError):
        pass  # a cell whose first and last stations cannot be joined still warms up
