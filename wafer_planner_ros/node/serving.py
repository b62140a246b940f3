"""
A roadmap ready to serve: its planning service, when it took over, and how it got there.

The worker's loading thread builds or loads a roadmap (``progress_reporter`` logs the
build), waits for the compiled kernels (``node.startup``), loads the cached station table
(``load_station_table``), which verifies every entry in full and leaves out those that
fail, and hands it all over as a ``Serving``: a ``service.planning.PlanningService`` with
the table as its cache. From then on the node is ready. When the table was not cached, it
is planned then, and when entries were rejected, those pairs (``build_station_table``;
``table_to_plan`` says whether), and the service's table is replaced by the planned one.
How a request is answered is the service's to say.
"""

from dataclasses import dataclass
import time
from typing import Optional

from wafer_planner_ros.planner import Planner
from wafer_planner_ros.roadmap.cache import CachedRoadmap
from wafer_planner_ros.service.planning import PlanningService, whole_curve
from wafer_planner_ros.service.table import build_and_store_table, load_table, StationTable
from wafer_planner_ros.service.table import TableError


@dataclass(frozen=True)
class Serving:
    """
    A loaded roadmap, its planning service, and when it took over (``time.time_ns()``).

    The service's station table belongs to this roadmap: it is set there once loaded or
    planned.
    """

    service: PlanningService
    cached: CachedRoadmap
    loaded_ns: int

    @property
    def planner(self) -> Planner:
        """Return the service's planner."""
        return self.service.planner


def progress_reporter(logger):
    """Return a roadmap build's progress callback that logs every tenth of the way."""
    last = [-1]

    def report(done: int, total: int, edges: int) -> None:
        tenth = 10 * done // max(total, 1)
        if tenth != last[0]:
            last[0] = tenth
            logger.info(f'building roadmap: {done}/{total} nodes, {edges} edges')
    return report


def load_station_table(planner: Planner, settings, logger) -> Optional[StationTable]:
    """Return the cached station table of a serving planner, or None (none usable)."""
    if not settings.station_table or settings.cache_dir is None:
        return None
    try:
        table = load_table(whole_curve(planner), settings.cache_dir)
    except TableError as exc:
        logger.info(f'station table: {exc}; planning it')
        return None
    for (start, goal), reason in sorted(table.rejected.items()):
        logger.warning(f'station table: {start} -> {goal} rejected, never answered from the '
                       f'file, planned again: {reason}')
    _report(table, logger)
    return table


def table_to_plan(table: Optional[StationTable], settings) -> bool:
    """Return whether a loaded station table (None: none) is to be planned, whole or in part."""
    return settings.station_table and (table is None or bool(table.rejected))


def build_station_table(planner: Planner, settings, logger,
                        loaded: Optional[StationTable] = None) -> StationTable:
    """Plan the station table of a serving planner (or the pairs ``loaded`` rejected); store it."""
    begun = time.monotonic()

    def progress(done: int, total: int, pair: str) -> None:
        logger.info(f'station table: {done}/{total} pairs planned ({pair}, '
                    f'{time.monotonic() - begun:.1f} s)')

    table = build_and_store_table(whole_curve(planner), settings.cache_dir, progress,
                                  logger.warning, loaded)
    _report(table, logger)
    return table


def _report(table: StationTable, logger) -> None:
    for (start, goal), reason in sorted(table.failures.items()):
        logger.warning(f'station table: {start} -> {goal} not planned: {reason}')
    logger.info(f'station table ready: {len(table)} pairs, '
                f'{"loaded" if table.loaded else "planned"} in {table.seconds:.2f} s')


def table_counts(serving: Optional[Serving]) -> dict:
    """
    Return the status counts of the serving roadmap's station table.

    ``station_table``: the pairs it holds; ``station_table_rejected``: the entries of the
    cached file it rejected on load. Both 0 without a table (or a serving roadmap).
    """
    stations = None if serving is None else serving.service.table
    return {'station_table': len(stations) if stations is not None else 0,
            'station_table_rejected': len(stations.rejected) if stations is not None else 0}
