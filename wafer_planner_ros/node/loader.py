"""
The node's roadmap loading: the cell, the roadmap, the kernels and the station table, in order.

The loading thread loads the roadmap, waits for the compiled kernels
(``startup.kernels_ready``: loaded since the process started, built ahead of time or from
numba's cache, or compiled when missing) and loads the cached station table, and only then
does the roadmap serve (handed meanwhile to the planning process,
``service.planning_process``, which plans what the table does not hold; a request that needs
it waits for that): the node is ready when it can answer, and until then the worker answers
every request ``ROADMAP_NOT_READY`` at once, saying why (``Phase``). What the cached station
tables lack is planned next, group by group, each handed to the service as it is
planned (``serving.table_groups``: the station pairs, then the empty moves, then the moves
through the ports, loaded and empty), and so are the pairs whose cached entries failed
verification (``busy_with: station_table``), pairs the tables do not hold yet being planned
within the budget meanwhile. A rebuild does the same while the previous roadmap serves, and
keeps it serving when it fails (``rebuild_failed`` in the status says why). A rebuild asked
while a load is under way is never refused: the table's planning stops once the pair being
planned is stored (so does a stopped node's), and the load starts again with the parameters
in force then. The loader is the worker's (``worker.PlanningWorker``): it shares the
worker's lock, and the worker reads the roadmaps it makes serve (``serving``, ``previous``)
and its ``phase``.
"""

import enum
import gc
import threading
import time
from typing import Callable, Optional

from wafer_planner_ros import giving_way
from wafer_planner_ros.cell.document import read_cell_file
from wafer_planner_ros.cell.model import Cell
from wafer_planner_ros.errors import WaferPlannerError
from wafer_planner_ros.node import markers
from wafer_planner_ros.node.faults import reason_of
from wafer_planner_ros.node.messages import Sent
from wafer_planner_ros.node.recording import Loaded, NodeRecording
from wafer_planner_ros.node.serving import build_station_tables, learn_tables
from wafer_planner_ros.node.serving import load_optima_files, load_station_tables
from wafer_planner_ros.node.serving import progress_reporter, Serving, store_optima_files
from wafer_planner_ros.node.serving import table_to_plan
from wafer_planner_ros.node.startup import kernels_ready, since_process_start
from wafer_planner_ros.planner import Planner, PlannerSettings
from wafer_planner_ros.roadmap.cache import load_or_build
from wafer_planner_ros.roadmap.graph import import_for_searches, RoadmapSettings
from wafer_planner_ros.service.planning import PlanningService
from wafer_planner_ros.service.planning_process import PlanningProcess
from wafer_planner_ros.service.settings import NodeSettings

STARTED, QUEUED = 'started', 'queued'
"""What ``RoadmapLoader.rebuild`` did: a load began, or one more follows the one under way."""


class Phase(enum.Enum):
    """What the loading side of the worker is doing (one at a time; ``PlanningWorker.status``)."""

    IDLE = None
    """No load under way: the serving roadmap (if any) serves."""
    LOADING = 'load'
    """Reading the cell, loading or building the roadmap, loading the station table."""
    COMPILING = 'kernels'
    """The compiled kernels are missing from numba's cache: they are being compiled."""
    PLANNING_TABLE = 'station_table'
    """No station table was cached, or entries were rejected: it is being planned."""
    STOPPING = 'stopping'
    """Stopped: the threads take no more work (it is never left)."""


class RoadmapLoader:
    """The loading thread, the roadmaps it makes serve and the load's state; see the module."""

    def __init__(self, lock: threading.Condition, settings: Callable[[], NodeSettings],
                 recording: NodeRecording, send: Callable, logger, stamp: Callable,
                 failed: Callable[[str], None], planning: PlanningProcess):
        """
        Make the loading thread (``start`` starts it); nothing serves yet.

        ``lock`` is the worker's: it guards what follows too and is notified at every
        change; ``settings``, ``recording``, ``send``, ``stamp`` as the worker's, ``logger``
        one that never raises; ``failed(message)`` says a failed load in the worker's last
        error (called with the lock held); ``planning``: the process that plans, handed
        every roadmap as it serves.
        """
        self.lock = lock
        self._planning = planning
        self._settings, self._recording, self._send = settings, recording, send
        self._logger, self._stamp, self._failed = logger, stamp, failed
        self.serving: Optional[Serving] = None
        self.previous: Optional[Serving] = None
        """The roadmap before the serving one, for requests received before it took over."""
        self.phase = Phase.LOADING
        """What the loading side does (``Phase``); the first load starts at once."""
        self.pending_ns: Optional[int] = None
        """When a loaded roadmap takes over, between being recorded and serving."""
        self.loading_cell = None
        self._again = False
        """A rebuild was asked while a load was under way: load again once it ends."""
        self.load_failed = False
        """The last load or rebuild failed (``last_load_error`` says why)."""
        self.last_load_error = ''
        self.thread = threading.Thread(target=self._load, name='wafer_planner_loader',
                                       daemon=True)

    def start(self) -> None:
        """Start the first load."""
        self.thread.start()

    @property
    def cell(self) -> Optional[Cell]:
        """Return the serving roadmap's cell, or before the first load the one it loads."""
        serving = self.serving
        return serving.planner.cell if serving is not None else self.loading_cell

    def rebuild(self) -> Optional[str]:
        """
        Reload the cell and roadmap with the current parameters; never refused while running.

        Return ``STARTED``; ``QUEUED`` while a load is under way (its station table's
        planning stops once the pair being planned is stored, and the load starts again
        with the parameters in force then: rebuilds asked meanwhile are one more load);
        None once stopping.
        """
        with self.lock:
            if self.phase is Phase.STOPPING:
                return None
            if self.phase is not Phase.IDLE:
                self._again = True
                return QUEUED
            self.phase = Phase.LOADING
        try:
            loader = threading.Thread(target=self._load, name='wafer_planner_loader',
                                      daemon=True)
            loader.start()
        except Exception:
            self.enter(Phase.IDLE)
            raise
        self.thread = loader
        return STARTED

    def _load(self) -> None:
        """Load or build the roadmap for the current parameters, again if asked; never raise."""
        giving_way.background()
        while True:
            try:
                self._load_roadmap()
            except Exception as exc:  # noqa: B902 - the node stays up and says why
                self._load_failed(exc)
            except BaseException:
                self.enter(Phase.IDLE)
                raise
            # Under one hold of the lock: a rebuild asked up to here is loaded next, one
            # asked after it finds the worker idle and starts its own load.
            with self.lock:
                again, self._again = self._again, False
                self.enter(Phase.LOADING if again else Phase.IDLE, locked=True)
                if not again or self.phase is Phase.STOPPING:
                    return

    def _table_stopped(self) -> bool:
        """Return True once the station table's planning should stop: a rebuild, or stop."""
        with self.lock:
            return self._again or self.phase is Phase.STOPPING

    def _load_roadmap(self) -> None:
        """Load the cell, the roadmap, the kernels and the station table; serve; plan the rest."""
        settings = self._settings()
        started = time.monotonic()
        try:
            cell_text = read_cell_file(settings.cell_file)  # the very text that is recorded
            cell = Cell.from_text(cell_text, str(settings.cell_file))
        except Exception as exc:  # noqa: B902 - the node stays up and says why
            self._load_failed(exc, settings.cell_file)
            return
        for note in cell.notes:
            self._logger.warning(f'{settings.cell_file}: {note}')
        try:
            with self.lock:
                if self.serving is None:  # joint requests are read with it meanwhile
                    self.loading_cell = cell
            self._logger.info(f'cell {cell.name} from {settings.cell_file}; loading or '
                              f'building a roadmap of {settings.nodes} nodes')
            cached = load_or_build(cell, RoadmapSettings(nodes=settings.nodes), settings.seed,
                                   settings.cache_dir, progress_reporter(self._logger))
            planner = Planner(cell, cached.roadmap,
                              PlannerSettings(sample_period=settings.sample_period))
            # Ready means able to answer: the kernels (loading since the process started)
            # and the cached station table first.
            kernels_ready(self._logger, self._kernels_compiling)
        except Exception as exc:  # noqa: B902 - the node stays up and says why
            self._load_failed(exc)
            return
        finally:
            self.enter(Phase.LOADING)  # the kernels are loaded (or failed): no longer compiling
        tables = {}
        try:
            tables = load_station_tables(planner, settings, self._logger)
        except Exception as exc:  # noqa: B902 - the roadmap serves without its table
            self._logger.error(f'station table not loaded: {reason_of(exc)}')
        learn_tables(planner, tables)  # drafts for requests near the stations
        roadmap = cached.roadmap
        # The planning process takes the roadmap meanwhile (a request waits for that: a few
        # tenths of a second once the process has started; the first request that needs it
        # hands it over again if this fails).
        key = self._planning.key()
        self._planning.hold_ahead(key, planner, lambda exc: self._logger.error(
            f'the planning process did not take the roadmap: {reason_of(exc)}'))
        # Everything loaded so far lives as long as the node: keep it out of the garbage
        # collector's full passes, which otherwise pause every thread for tens of ms.
        gc.collect()
        gc.freeze()
        # Recorded before it serves: every recorded query comes after the load it used.
        # Requests received from this instant on wait (a moment) for it to serve.
        loaded_ns = time.time_ns()
        with self.lock:
            self.pending_ns = loaded_ns
        try:
            self._recording.loaded(Loaded(cell_text, {
                'cell': cell.name, 'cell_file': str(settings.cell_file),
                'cell_digest': cell.digest, 'roadmap_hash': roadmap.digest,
                'roadmap_nodes': str(settings.nodes), 'roadmap_seed': str(roadmap.seed),
                'roadmap_edges': str(roadmap.edge_count)}, loaded_ns))
        except Exception as exc:  # noqa: B902 - a recording's failure is not the roadmap's
            self._logger.error(f'the roadmap load was not recorded: {reason_of(exc)}')
        finally:
            with self.lock:
                self.pending_ns = None  # first: planning waits while it is set
                self.previous = self.serving
                serving = self.serving = Serving(PlanningService(planner, tables=tables),
                                                 cached, loaded_ns, key)
                if table_to_plan(planner, tables, settings):
                    self.enter(Phase.PLANNING_TABLE, locked=True)
                self.loading_cell = None
                self.load_failed, self.last_load_error = False, ''
                self.lock.notify_all()
        self._logger.info(
            f'ready: roadmap {roadmap.node_count} nodes, {roadmap.edge_count} edges, hash '
            f'{roadmap.digest[:12]}, {cached.status.value} in {cached.seconds:.2f} s; station '
            f'table {_held(tables) or "to plan"}'
            f' (ready {time.monotonic() - started:.2f} s after loading began'
            f'{since_process_start()})')
        try:
            import_for_searches()  # the station table's plans are made here
        except ImportError as exc:  # the first plan says it too
            self._logger.error(f'the planner cannot import: {reason_of(exc)}')
        try:
            roadmap_markers = markers.roadmap_markers(cell, roadmap, settings.frame_id,
                                                      self._stamp())
            self._send((Sent.MARKERS, roadmap_markers, 0))
            self._recording.markers(roadmap_markers)
        except Exception as exc:  # noqa: B902 - the roadmap serves without its picture
            self._logger.error(f'roadmap markers not published: {reason_of(exc)}')
        try:
            load_optima_files(self._planning, key, planner, settings, self._logger,
                              self._table_stopped)
        except Exception as exc:  # noqa: B902 - only requests near them are slower
            self._logger.error(f'optima not loaded: {reason_of(exc)}')
        if not table_to_plan(planner, tables, settings):
            return

        def publish(load: str, table) -> None:
            with self.lock:
                serving.service.set_table(load, table)
            learn_tables(planner, {load: table})

        try:
            build_station_tables(planner, settings, self._logger, tables, publish,
                                 self._table_stopped)
        except Exception as exc:  # noqa: B902 - the roadmap serves without its table
            self._logger.error(f'station table not planned: {reason_of(exc)}')
        try:
            store_optima_files(self._planning, key, planner, settings, self._logger)
        except Exception as exc:  # noqa: B902 - only requests near them are slower
            self._logger.error(f'optima not stored: {reason_of(exc)}')
        self.enter(Phase.LOADING)  # the table planned: the load ends

    def _kernels_compiling(self) -> None:
        """Say, in the status and to requests, that the kernels are being compiled."""
        self.enter(Phase.COMPILING)

    def enter(self, phase: Phase, locked: bool = False) -> None:
        """Enter ``phase`` (never leaving ``STOPPING``); ``locked``: the lock is held."""
        if not locked:
            with self.lock:
                self.enter(phase, locked=True)
            return
        if self.phase is not Phase.STOPPING:
            self.phase = phase
            self.lock.notify_all()

    def _load_failed(self, exc: Exception, cell_file=None) -> None:
        """Say why the load failed; the serving roadmap, if any, serves on."""
        kind = '' if isinstance(exc, (WaferPlannerError, ValueError, OSError)) else \
            'internal error: '
        reason = f'{kind}{reason_of(exc, with_type=bool(kind))}'
        if cell_file is not None and str(cell_file) not in reason:
            reason = f'cell file {cell_file}: {reason}'  # say which file it is
        with self.lock:
            serving = self.serving
            self.load_failed, self.last_load_error = True, reason
            message = f'roadmap not loaded: {reason}' if serving is None else (
                f'rebuild failed: {reason}; serving the previous roadmap '
                f'{serving.cached.roadmap.digest[:12]}')
            self._failed(message)
        self._logger.error(message)


def _held(tables: dict) -> str:
    """Return 'of 12 loaded pairs, 12 empty pairs' for the station tables ('' for none)."""
    held = ', '.join(f'{len(table)} {load} pairs' for load, table in tables.items())
    return f'of {held}' if held else ''
