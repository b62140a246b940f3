"""
A roadmap ready to serve: its planning service, when it took over, and how it got there.

The worker's loading thread builds or loads a roadmap (``progress_reporter`` logs the
build), waits for the compiled kernels (``node.startup``), loads the cached station tables
(``load_station_tables``: one per limit set), which verify every entry in full and leave
out those that fail, and hands it all over as a ``Serving``: a
``service.planning.PlanningService`` with the tables as its cache. From then on the node is
ready (the planning process, which plans what the tables do not hold, takes the roadmap
meanwhile: ``service.planning_process``). What the tables lack of what they are to hold
(``table_groups``: the station pairs loaded; with ``planning.station_table_ports`` also
empty, then the port pairs loaded and empty), or rejected, is planned then, group by group
(``build_station_tables``; ``table_to_plan`` says whether), the table stored and handed to
the service as each pair is planned: each pair is answered from the table a second or two
after the one before. How a request is answered is the service's to say. The tables'
curves are handed to the planning process as optima (``learn_tables``), which reads,
verifies and stores the optima files (``load_optima_files``, ``store_optima_files``).
"""

from dataclasses import dataclass
import time
from typing import Callable, Dict, Optional

from wafer_planner_ros.cell.limits import EMPTY, LOADED
from wafer_planner_ros.cell.stations import station_pairs
from wafer_planner_ros.planner import Planner
from wafer_planner_ros.roadmap.cache import CachedRoadmap
from wafer_planner_ros.service.optima_store import learn_table
from wafer_planner_ros.service.planning import PlanningService, whole_curve
from wafer_planner_ros.service.table import build_and_store_table, lacking, load_table
from wafer_planner_ros.service.table import port_pairs, StationTable, TableError


OPTIMA_VERIFIED_AT_ONCE = 4
"""Optima of the cached files the planning process verifies in one go (a few ms each)."""


@dataclass(frozen=True)
class Serving:
    """
    A loaded roadmap, its planning service, and when it took over (``time.time_ns()``).

    The service's station table belongs to this roadmap: it is set there once loaded or
    planned. ``key``: the roadmap's in the planning process
    (``service.planning_process``), which plans what the table does not hold.
    """

    service: PlanningService
    cached: CachedRoadmap
    loaded_ns: int
    key: int

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


def table_groups(planner: Planner, settings) -> list:
    """
    Return what the station tables are to hold, in the order planned: [(load, pairs)].

    The station pairs loaded; with ``station_table_ports`` the same empty, then the port
    pairs loaded and empty. None without ``station_table``.
    """
    if not settings.station_table:
        return []
    groups = [(LOADED, station_pairs(planner.cell))]
    ports = port_pairs(planner.cell)
    if settings.station_table_ports:
        groups.append((EMPTY, station_pairs(planner.cell)))
        groups += [(load, ports) for load in (LOADED, EMPTY) if ports]
    return groups


def load_station_tables(planner: Planner, settings, logger) -> Dict[str, StationTable]:
    """Return the cached station tables of a serving planner by limit set (those usable)."""
    if settings.cache_dir is None:
        return {}
    tables = {}
    for load in dict.fromkeys(load for load, _ in table_groups(planner, settings)):
        try:
            table = load_table(whole_curve(planner).for_load(load), settings.cache_dir)
        except TableError as exc:
            logger.info(f'station table ({load}): {exc}; planning it')
            continue
        for (start, goal), reason in sorted(table.rejected.items()):
            logger.warning(f'station table ({load}): {start} -> {goal} rejected, never '
                           f'answered from the file, planned again: {reason}')
        _report(table, logger)
        tables[load] = table
    return tables


def load_optima_files(planning, key: int, planner: Planner, settings, logger,
                      stopped: Callable[[], bool] = lambda: False) -> None:
    """
    Have the planning process read and verify the cached optima of the roadmap under ``key``.

    Of every limit set (``optima_store``), in the planning process: read, then verified in
    full there ``OPTIMA_VERIFIED_AT_ONCE`` at a time (a request waits for no more than
    those); those that fail are left out and said here; a file that cannot be used is
    said and passed over (only requests near its optima are slower). ``stopped()`` True
    (a rebuild, the node stopping) ends it between two goes.
    """
    if settings.cache_dir is None:
        return
    begun = time.monotonic()
    found = {}
    for load, path, count in planning.read_optima(key, planner, settings.cache_dir):
        if isinstance(path, str):
            logger.info(f'optima ({load}): {path}')
        else:
            found[load] = [path, count, 0]
    left = sum(count for _, count, _ in found.values())
    while left and not stopped():
        done, left = planning.verify_optima(key, planner, OPTIMA_VERIFIED_AT_ONCE)
        for load, kept, rejected in done:
            found[load][2] += kept
            for reason in rejected:
                logger.warning(f'optima ({load}): {reason}; left out')
        time.sleep(0.001)  # a request waiting for the planning process goes first
    for load, (path, count, kept) in found.items():
        logger.info(f'optima ({load}): {kept} of {count} in {path.name} passed verification'
                    f' and are kept ({time.monotonic() - begun:.2f} s)')


def learn_tables(planner: Planner, tables: Dict[str, StationTable]) -> None:
    """Keep the station tables' curves as optima of ``planner`` (``optima_store.learn_table``)."""
    for load, table in tables.items():
        learn_table(whole_curve(planner).for_load(load), table)


def store_optima_files(planning, key: int, planner: Planner, settings, logger,
                       turn: Optional[float] = None) -> None:
    """
    Have the planning process store the optima it keeps of the roadmap under ``key``.

    (``PlanningProcess.store_optima``; with a cache directory.) ``turn``: seconds to wait
    for a plan under way to end; not stored when it has not (said).
    """
    if settings.cache_dir is None:
        return
    stored = planning.store_optima(key, planner, settings.cache_dir, turn)
    if stored is None:
        logger.info('optima not stored: a plan was under way')
        return
    for load, path in stored:
        if isinstance(path, str):
            logger.warning(f'optima ({load}) not stored: {path}')


def table_to_plan(planner: Planner, tables: Dict[str, StationTable], settings) -> bool:
    """Return whether the loaded station tables lack any pair they are to hold."""
    groups = table_groups(planner, settings)
    return any(lacking(tables.get(load), pairs) for load, pairs in groups)


def build_station_tables(planner: Planner, settings, logger, tables: Dict[str, StationTable],
                         publish: Callable[[str, StationTable], None],
                         stopped: Callable[[], bool] = lambda: False) -> None:
    """
    Plan what the station tables lack, group by group (``table_groups``), pair by pair.

    ``tables``: those loaded; after each pair the table is stored and handed on,
    ``publish(load, table)``: a pair is answered from the table as soon as it is planned
    (a second or two each). Before each pair ``stopped()`` is asked: True ends the planning
    there (the pairs planned are stored; a later load plans the rest).
    """
    tables = dict(tables)
    whole = whole_curve(planner)  # one planner per limit set: its transfers serve every pair
    for load, pairs in table_groups(planner, settings):
        missing = lacking(tables.get(load), pairs)
        if not missing:
            continue
        begun = time.monotonic()
        logger.info(f'station table ({load}): planning {len(missing)} pairs, e.g. '
                    f'{"->".join(missing[0])}')
        # The empty moves take the loaded one's curve where that is faster (and verifies).
        donor = tables.get(LOADED) if load == EMPTY else None
        for done, pair in enumerate(missing, 1):
            if stopped():
                logger.info(f'station table ({load}): planning stopped after {done - 1}/'
                            f'{len(missing)} pairs (the rest are planned on a later load)')
                return
            table = tables[load] = build_and_store_table(
                whole.for_load(load), settings.cache_dir, None,
                logger.warning, tables.get(load), [pair], donor)
            publish(load, table)
            logger.info(f'station table ({load}): {done}/{len(missing)} pairs planned '
                        f'({"->".join(pair)}, {time.monotonic() - begun:.1f} s)')
        _report(table, logger)


def _report(table: StationTable, logger) -> None:
    for (start, goal), reason in sorted(table.failures.items()):
        logger.warning(f'station table ({table.load}): {start} -> {goal} not planned: {reason}')
    logger.info(f'station table ({table.load}) ready: {len(table)} pairs, '
                f'{"loaded" if table.loaded else "planned"} in {table.seconds:.2f} s')


def table_counts(serving: Optional[Serving]) -> dict:
    """
    Return the status counts of the serving roadmap's station tables.

    ``station_table``: the pairs the loaded moves' table holds; ``station_table_empty``: the
    empty moves'; ``station_table_rejected``: the entries of the cached files they rejected
    on load. Each 0 without a table (or a serving roadmap).
    """
    tables = {} if serving is None else serving.service.tables
    return {'station_table': len(tables[LOADED]) if LOADED in tables else 0,
            'station_table_empty': len(tables[EMPTY]) if EMPTY in tables else 0,
            'station_table_rejected': sum(len(table.rejected) for table in tables.values())}
