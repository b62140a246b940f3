"""
The node's planning worker: planning, table-answering, watchdog and loading threads.

The planning thread plans one request at a time. Requests wait in a bounded backlog
(``planning.max_queue``; beyond it the answer is ``BUSY``). A station pair that the station
table holds never waits behind planning: the answering thread gives it at once (from a
queue of its own, as long). Every queued request is answered by ``planning.timeout``
seconds after its receipt: the watchdog thread answers ``TIMEOUT`` at that instant for one
not answered yet (waiting or still being planned), and a plan finished later is dropped,
never sent. The loading thread loads the roadmap, waits for the compiled kernels
(``startup.kernels_ready``: loaded since the process started, built ahead of time or from
numba's cache, or compiled when missing) and loads the cached station table, and only then
does the roadmap serve: the node is ready when it can answer, and until then every request
is answered ``ROADMAP_NOT_READY`` at once, saying why. What the cached station tables lack
is planned next, group by group, each handed to the service as it is planned
(``serving.table_groups``: the station pairs, then the empty moves, then the moves through
the ports, loaded and empty), and so are the pairs whose
cached entries failed verification (``busy_with: station_table``), pairs the tables do not
hold yet being planned within the budget meanwhile. A rebuild does the same while the
previous roadmap serves, and keeps it serving when it fails (``rebuild_failed`` in the
status says why). A rebuild asked while a load is under way is never refused: the table's
planning stops once the pair being planned is stored (so does a stopped node's), and the
load starts again with the parameters in force then. Each request is planned on the
roadmap in force when it was received, the one a recording pairs it with, and answered as
``service.planning`` says. The worker never
publishes: it hands every message, already serialised, to ``send``, which the node
publishes from its executor. Every request gets exactly one answer, whatever happens: a
failure of the node itself is answered ``INTERNAL`` with the reason. On stop the threads
are left as they are (daemons): the node never waits for a plan or the pair of the table
being planned.
"""

from collections import deque
import enum
import gc
import heapq
import threading
import time
from typing import Callable, Optional

from wafer_planner_ros import kernels
from wafer_planner_ros.cell.document import read_cell_file
from wafer_planner_ros.cell.model import Cell
from wafer_planner_ros.errors import ErrorCode, PlanningError, WaferPlannerError
from wafer_planner_ros.node import markers, messages
from wafer_planner_ros.node.faults import reason_of, SafeLogger
from wafer_planner_ros.node.messages import Sent
from wafer_planner_ros.node.recording import Loaded, NodeRecording
from wafer_planner_ros.node.serving import build_station_tables, load_station_tables
from wafer_planner_ros.node.serving import progress_reporter, Serving
from wafer_planner_ros.node.serving import table_counts, table_to_plan
from wafer_planner_ros.node.startup import (import_for_planning, kernels_ready,
                                            since_process_start)
from wafer_planner_ros.planner import Planner, PlannerSettings
from wafer_planner_ros.roadmap.cache import load_or_build
from wafer_planner_ros.roadmap.graph import RoadmapSettings
from wafer_planner_ros.service.planning import PlanningService
from wafer_planner_ros.service.settings import NodeSettings

PREVIOUS_KEPT_NS = 1_000_000_000
"""How long the previous roadmap is kept for requests received before a new one serves but
not yet queued (the executor hands them over within milliseconds)."""
NOT_LOADED = 'the roadmap is being loaded or built'
STARTED, QUEUED = 'started', 'queued'
"""What ``PlanningWorker.rebuild`` did: a load began, or one more follows the one under way."""


class Phase(enum.Enum):
    """What the loading side of the worker is doing (one at a time; see ``Worker.status``)."""

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


class PlanningWorker:
    """The loading, planning, answering and watchdog threads and their state; see the module."""

    def __init__(self, settings: Callable[[], NodeSettings], recording: NodeRecording,
                 send: Callable, logger, stamp: Callable):
        """
        Start the threads; the loading one first loads the roadmap.

        ``settings`` returns the node's current settings; ``send(*items)`` hands
        (kind, message, query number) items to the executor and never raises; ``stamp``
        returns a ROS time.
        """
        self._settings, self._recording, self._send = settings, recording, send
        self._logger, self._stamp = SafeLogger(logger), stamp
        self.lock = threading.Condition()
        """
        Guards the queues, the open queries, the roadmaps, the load state, the station table
        and the counts; wakes the threads.

        ``cell`` and ``answer_error`` read ``_serving`` without it: one reference, replaced
        whole under the lock, so a read sees the old roadmap or the new one, never half.
        """
        self._backlog = deque()
        """(number, request, received monotonic, received ns) of the requests to plan."""
        self._lane = deque()
        """The same of station pairs the station table holds: answered at once."""
        self._open = {}
        """number -> (request, deadline, timeout) of every queued query not yet answered."""
        self._deadlines = []
        """Heap of (deadline, number) of the open queries, for the watchdog."""
        self._planned = set()
        """Numbers of the queries being planned (not waiting)."""
        self._serving: Optional[Serving] = None
        self._previous: Optional[Serving] = None
        """The roadmap before the serving one, for requests received before it took over."""
        self._phase = Phase.LOADING
        """What the loading side does (``Phase``); the first load starts at once."""
        self._pending_ns: Optional[int] = None
        """When a loaded roadmap takes over, between being recorded and serving."""
        self._loading_cell = None
        self._again = False
        """A rebuild was asked while a load was under way: load again once it ends."""
        self.load_failed = False
        """The last load or rebuild failed (``last_load_error`` says why)."""
        self.last_load_error = ''
        self.counts = {'served': 0, 'failed': 0}
        self.last_error = ''
        self._threads = [threading.Thread(target=target, name=name, daemon=True) for name, target
                         in (('wafer_planner_worker', lambda: self._work(self._backlog)),
                             ('wafer_planner_table', lambda: self._work(self._lane)),
                             ('wafer_planner_watchdog', self._watch),
                             ('wafer_planner_loader', self._load))]
        for thread in self._threads:
            thread.start()

    @property
    def cell(self) -> Optional[Cell]:
        """Return the serving roadmap's cell, or before the first load the one it loads."""
        serving = self._serving
        return serving.planner.cell if serving is not None else self._loading_cell

    # ----------------------------------------------------------------- from the executor

    def enqueue(self, number: int, request, received: float,
                received_ns: Optional[int] = None) -> None:
        """
        Queue request ``number`` or refuse it; never raise.

        ``received``: its receipt (``time.monotonic()``); ``received_ns``: the same as
        recorded (``time.time_ns()``), which picks the roadmap it is planned on.
        """
        try:
            settings = self._settings()
            with self.lock:
                serving = self._serving
                held = serving is not None and serving.service.holds(
                    request.start, request.goal, request.load)
                waiting = None if serving is None else self._lane if held else self._backlog
                if waiting is None:
                    code, message = ErrorCode.ROADMAP_NOT_READY, f'not ready: {self._not_ready()}'
                elif self._waiting(waiting) >= settings.max_queue:
                    code = ErrorCode.BUSY
                    message = (f'busy: {settings.max_queue} requests are already waiting '
                               '(planning.max_queue)')
                else:
                    waiting.append((number, request, received,
                                    time.time_ns() if received_ns is None else received_ns))
                    deadline = received + settings.timeout
                    self._open[number] = (request, deadline, settings.timeout)
                    heapq.heappush(self._deadlines, (deadline, number))
                    self.lock.notify_all()
                    return
        except Exception as exc:  # noqa: B902 - every request gets its one answer
            self.answer_internal(number, request.request_id, exc, 'queueing the request',
                                 request.start, request.goal)
            return
        self.answer_error(number, request.request_id, code, message, request.start,
                          request.goal)

    def rebuild(self) -> Optional[str]:
        """
        Reload the cell and roadmap with the current parameters; never refused while running.

        Return ``STARTED``; ``QUEUED`` while a load is under way (its station table's
        planning stops once the pair being planned is stored, and the load starts again
        with the parameters in force then: rebuilds asked meanwhile are one more load);
        None once stopping.
        """
        with self.lock:
            if self._phase is Phase.STOPPING:
                return None
            if self._phase is not Phase.IDLE:
                self._again = True
                return QUEUED
            self._phase = Phase.LOADING
        try:
            loader = threading.Thread(target=self._load, name='wafer_planner_loader',
                                      daemon=True)
            loader.start()
        except Exception:
            self._enter(Phase.IDLE)
            raise
        self._threads[-1] = loader
        return STARTED

    def answer_error(self, number, request_id, code, message, start, goal,
                     planning_ms=None, roadmap=None) -> None:
        """Send the error answer of query ``number``; never raise."""
        try:
            if roadmap is None and self._serving is not None:
                roadmap = self._serving.cached.roadmap
            status = messages.result_status(
                request_id, 'error', f'{code.value}: {message}',
                messages.error_values(code.value, roadmap, start, goal, planning_ms))
        except Exception as exc:  # noqa: B902 - still one answer: without the values
            code, message = ErrorCode.INTERNAL, \
                f'internal error: answering {code.value} failed: {reason_of(exc)}'
            try:
                status = messages.result_status(str(request_id), 'error',
                                                f'{code.value}: {message}',
                                                {'code': code.value})
            except Exception as again:  # noqa: B902 - nothing left to answer with
                self._logger.error(f'query {number}: no answer could be made: {reason_of(again)}')
                return
        self._logger.warning(f'request {request_id or "(no id)"}: {code.value}: {message}')
        with self.lock:
            self.counts['failed'] += 1
            self.last_error = f'{request_id}: {code.value}: {message}'
        self._send((Sent.RESULT, status, number))

    def answer_internal(self, number, request_id, exc: BaseException, doing: str,
                        start=None, goal=None, planning_ms=None, roadmap=None) -> None:
        """Send the ``INTERNAL`` answer of query ``number``, failed while ``doing``."""
        self._logger.error(f'request {request_id or "(no id)"}: internal error while '
                           f'{doing}: {reason_of(exc)}'[:2000])
        self.answer_error(number, request_id, ErrorCode.INTERNAL,
                          f'internal error while {doing}: {reason_of(exc)}', start, goal,
                          planning_ms, roadmap)

    def status(self) -> dict:
        """Return the worker's part of ``~/get_status``."""
        settings = self._settings()
        with self.lock:
            serving = self._serving
            roadmap = serving.cached.roadmap if serving is not None else None
            cell = serving.planner.cell if serving is not None else self._loading_cell
            return {
                'ready': serving is not None,
                'busy_with': self._phase.value if self._phase not in (
                    Phase.IDLE, Phase.STOPPING) else 'plan' if self._planned else None,
                'cell': cell.name if cell is not None else None,
                'nodes': roadmap.node_count if roadmap is not None else 0,
                'edges': roadmap.edge_count if roadmap is not None else 0,
                'hash': roadmap.digest if roadmap is not None else '',
                'seed': roadmap.seed if roadmap is not None else settings.seed,
                'queue': self._waiting(self._backlog),
                'served': self.counts['served'], 'failed': self.counts['failed'],
                'last_error': self.last_error,
                'rebuild_failed': self.load_failed,
                'last_rebuild_error': self.last_load_error,
                **table_counts(serving),
                'kernels_compiled': kernels.compiled_count(),
                'kernels_ahead': kernels.ahead_count(),
            }

    def request_stop(self) -> None:
        """Have the threads stop taking work (see ``join``)."""
        self._enter(Phase.STOPPING)

    def join(self, timeout: float) -> None:
        """
        Wait up to ``timeout`` seconds in all for the threads to stop.

        A plan, a roadmap build or a station table being planned is not waited for beyond
        that: the threads are daemons, ended with the process.
        """
        deadline = time.monotonic() + timeout
        for thread in list(self._threads):
            thread.join(max(0.0, deadline - time.monotonic()))

    # ----------------------------------------------------------------- planning

    def _not_ready(self) -> str:
        """Return why the node cannot answer yet; call with the lock held."""
        if self._phase is Phase.COMPILING:
            return ('the planning kernels are being compiled for this machine (about 40 s; '
                    '`wafer-kernels` compiles them ahead)')
        if self.load_failed and self._phase is Phase.IDLE:
            return f'roadmap not loaded: {self.last_load_error}'
        return NOT_LOADED

    def _work(self, queue: deque) -> None:
        """Answer the requests of ``queue`` one at a time until stopped."""
        while True:
            with self.lock:
                while not queue and self._phase is not Phase.STOPPING:
                    self.lock.wait()
                if self._phase is Phase.STOPPING:
                    return
                item = queue.popleft()
                if item[0] not in self._open:
                    continue  # answered TIMEOUT while it waited
                self._planned.add(item[0])
                # Its roadmap, resolved as it leaves the queue (``_serving_for`` frees the
                # previous roadmap once no queued request needs it).
                serving = self._serving_for(item[3])
            try:
                self._plan(serving, *item[:3])
            except Exception as exc:  # noqa: B902 - the thread outlives any one request
                self._logger.error(f'planning thread: {reason_of(exc)}')
            finally:
                with self.lock:
                    self._planned.discard(item[0])

    def _watch(self) -> None:
        """Answer ``TIMEOUT`` for every query still open at its deadline, at that instant."""
        while True:
            with self.lock:
                expired = []
                while not expired and self._phase is not Phase.STOPPING:
                    now = time.monotonic()
                    while self._deadlines and self._deadlines[0][0] <= now:
                        number = heapq.heappop(self._deadlines)[1]
                        if number in self._open:
                            expired.append((number, self._open.pop(number),
                                            number in self._planned, len(self._planned)))
                    if not expired:
                        self.lock.wait(self._deadlines[0][0] - now if self._deadlines
                                       else None)
                if self._phase is Phase.STOPPING:
                    return
            for number, (request, _, timeout), planned, busy in expired:
                doing = 'its planning did not finish' if planned else \
                    f'it waited behind {busy} request{"s" * (busy != 1)} being planned'
                self.answer_error(number, request.request_id, ErrorCode.TIMEOUT,
                                  f'not answered within planning.timeout ({timeout:g} s) of '
                                  f'its receipt: {doing}', request.start, request.goal)

    def _waiting(self, queue: deque) -> int:
        """Return how many of ``queue``'s requests wait unanswered; call with the lock held."""
        return sum(item[0] in self._open for item in queue)

    def _claim(self, number: int) -> bool:
        """
        Return True once for an open query (it is then answered), else False.

        False too once its deadline has come: the watchdog answers it ``TIMEOUT`` then,
        however late its own turn.
        """
        with self.lock:
            entry = self._open.get(number)
            if entry is None or time.monotonic() >= entry[1]:
                return False
            del self._open[number]
            return True

    def _serving_for(self, received_ns: int) -> Optional[Serving]:
        """Return the roadmap in force at ``received_ns``; call with the lock held."""
        while self._pending_ns is not None and received_ns >= self._pending_ns:
            self.lock.wait()  # recorded as taking over, not serving yet: a moment
        serving, previous = self._serving, self._previous
        if serving is not None and received_ns < serving.loaded_ns and previous is not None:
            return previous
        if previous is not None and serving is not None \
                and time.time_ns() - serving.loaded_ns > PREVIOUS_KEPT_NS \
                and all(item[3] >= serving.loaded_ns for queued in (self._backlog, self._lane)
                        for item in queued):
            self._previous = None  # no request needs it any more: free its memory
        return serving

    def _plan(self, serving: Serving, number: int, request, received: float) -> None:
        """Answer a request on ``serving``, unless the watchdog has (the plan is then dropped)."""
        roadmap, begun, doing = None, None, 'planning'
        try:
            settings = self._settings()
            with self.lock:
                deadline = self._open.get(number, (None, received + settings.timeout))[1]
            service = serving.service.using(settings.optimise_budget, settings.sample_period)
            planner, roadmap = service.planner, serving.cached.roadmap
            joints = planner.cell.robot.joint_names
            angles = any(not isinstance(end, str) for end in (request.start, request.goal))
            if angles and request.read_for and tuple(request.read_for) != joints:
                # Read for the cell that served at receipt, planned on another (a rebuild
                # in between changed the joints): its angles would mean other joints.
                self._answer_error(number, request, ErrorCode.JOINT_MISMATCH,
                                   f'the request was read for joints {list(request.read_for)}, '
                                   f'but the roadmap it is planned on has {list(joints)} (a '
                                   'rebuild changed them): send it again', roadmap=roadmap)
                return
            begun = time.monotonic()
            try:
                result = service.answer(request.start, request.goal, deadline, request.load)
            except PlanningError as exc:
                self._answer_error(number, request, exc.code, exc.message,
                                   (time.monotonic() - begun) * 1000.0, roadmap)
                return
            doing, stamp = 'answering', self._stamp()
            # The trajectory and its result go together (the node records both, then
            # publishes them); the markers, for people, after both.
            answer = messages.plan_answer(result, request, roadmap, joints, stamp,
                                          (time.monotonic() - received) * 1000.0)
        except Exception as exc:  # noqa: B902 - every request gets its one answer
            if self._claim(number):
                self.answer_internal(number, request.request_id, exc, doing, request.start,
                                     request.goal, None if begun is None
                                     else (time.monotonic() - begun) * 1e3, roadmap)
            return
        if not self._claim(number):
            self._logger.info(f'request {request.request_id or "(no id)"}: planned after it '
                              'was answered TIMEOUT; not sent')
            return
        self._send((Sent.ANSWER, answer, number))
        with self.lock:
            self.counts['served'] += 1
        try:
            path = markers.path_markers(planner.cell, result, settings.frame_id, stamp)
        except Exception as exc:  # noqa: B902 - answered already: only the picture is lost
            self._logger.error(f'request {request.request_id}: no path markers: {reason_of(exc)}')
            return
        self._send((Sent.PATH, path, number))

    def _answer_error(self, number: int, request, code, message: str, planning_ms=None,
                      roadmap=None) -> None:
        """Send the error answer of a queued query, unless it was answered already."""
        if self._claim(number):
            self.answer_error(number, request.request_id, code, message, request.start,
                              request.goal, planning_ms, roadmap)

    # ----------------------------------------------------------------- loading

    def _load(self) -> None:
        """Load or build the roadmap for the current parameters, again if asked; never raise."""
        while True:
            try:
                self._load_roadmap()
            except Exception as exc:  # noqa: B902 - the node stays up and says why
                self._load_failed(exc)
            except BaseException:
                self._enter(Phase.IDLE)
                raise
            # Under one hold of the lock: a rebuild asked up to here is loaded next, one
            # asked after it finds the worker idle and starts its own load.
            with self.lock:
                again, self._again = self._again, False
                self._enter(Phase.LOADING if again else Phase.IDLE, locked=True)
                if not again or self._phase is Phase.STOPPING:
                    return

    def _table_stopped(self) -> bool:
        """Return True once the station table's planning should stop: a rebuild, or stop."""
        with self.lock:
            return self._again or self._phase is Phase.STOPPING

    def _load_roadmap(self) -> None:
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
                if self._serving is None:  # joint requests are read with it meanwhile
                    self._loading_cell = cell
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
            self._enter(Phase.LOADING)  # the kernels are loaded (or failed): no longer compiling
        tables = {}
        try:
            tables = load_station_tables(planner, settings, self._logger)
        except Exception as exc:  # noqa: B902 - the roadmap serves without its table
            self._logger.error(f'station table not loaded: {reason_of(exc)}')
        roadmap = cached.roadmap
        # Everything loaded so far lives as long as the node: keep it out of the garbage
        # collector's full passes, which otherwise pause every thread for tens of ms.
        gc.collect()
        gc.freeze()
        # Recorded before it serves: every recorded query comes after the load it used.
        # Requests received from this instant on wait (a moment) for it to serve.
        loaded_ns = time.time_ns()
        with self.lock:
            self._pending_ns = loaded_ns
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
                self._pending_ns = None  # first: planning waits while it is set
                self._previous = self._serving
                serving = self._serving = Serving(PlanningService(planner, tables=tables),
                                                  cached, loaded_ns)
                if table_to_plan(planner, tables, settings):
                    self._enter(Phase.PLANNING_TABLE, locked=True)
                self._loading_cell = None
                self.load_failed, self.last_load_error = False, ''
                self.lock.notify_all()
        self._logger.info(
            f'ready: roadmap {roadmap.node_count} nodes, {roadmap.edge_count} edges, hash '
            f'{roadmap.digest[:12]}, {cached.status.value} in {cached.seconds:.2f} s; station '
            f'table {_held(tables) or "to plan"}'
            f' (ready {time.monotonic() - started:.2f} s after loading began'
            f'{since_process_start()})')
        try:
            import_for_planning()
        except ImportError as exc:  # the first plan says it too
            self._logger.error(f'the planner cannot import: {reason_of(exc)}')
        try:
            roadmap_markers = markers.roadmap_markers(cell, roadmap, settings.frame_id,
                                                      self._stamp())
            self._send((Sent.MARKERS, roadmap_markers, 0))
            self._recording.markers(roadmap_markers)
        except Exception as exc:  # noqa: B902 - the roadmap serves without its picture
            self._logger.error(f'roadmap markers not published: {reason_of(exc)}')
        if not table_to_plan(planner, tables, settings):
            return

        def publish(load: str, table) -> None:
            with self.lock:
                serving.service.set_table(load, table)

        try:
            build_station_tables(planner, settings, self._logger, tables, publish,
                                 self._table_stopped)
        except Exception as exc:  # noqa: B902 - the roadmap serves without its table
            self._logger.error(f'station table not planned: {reason_of(exc)}')
        self._enter(Phase.LOADING)  # the table planned: the load ends

    def _kernels_compiling(self) -> None:
        """Say, in the status and to requests, that the kernels are being compiled."""
        self._enter(Phase.COMPILING)

    def _enter(self, phase: Phase, locked: bool = False) -> None:
        """Enter ``phase`` (never leaving ``STOPPING``); ``locked``: the lock is held."""
        if not locked:
            with self.lock:
                self._enter(phase, locked=True)
            return
        if self._phase is not Phase.STOPPING:
            self._phase = phase
            self.lock.notify_all()

    def _load_failed(self, exc: Exception, cell_file=None) -> None:
        """Say why the load failed; the serving roadmap, if any, serves on."""
        kind = '' if isinstance(exc, (WaferPlannerError, ValueError, OSError)) else \
            'internal error: '
        reason = f'{kind}{reason_of(exc, with_type=bool(kind))}'
        if cell_file is not None and str(cell_file) not in reason:
            reason = f'cell file {cell_file}: {reason}'  # say which file it is
        with self.lock:
            serving = self._serving
            self.load_failed, self.last_load_error = True, reason
            self.last_error = f'roadmap not loaded: {reason}' if serving is None else (
                f'rebuild failed: {reason}; serving the previous roadmap '
                f'{serving.cached.roadmap.digest[:12]}')
        self._logger.error(self.last_error)


def _held(tables: dict) -> str:
    """Return 'of 12 loaded pairs, 12 empty pairs' for the station tables ('' for none)."""
    held = ', '.join(f'{len(table)} {load} pairs' for load, table in tables.items())
    return f'of {held}' if held else ''
