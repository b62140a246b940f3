"""
The node's planning worker: the planning, table-answering and watchdog threads, and the loader.

The planning thread takes one request at a time and has it planned in the planning process
(``service.planning_process``: a child at a lower priority, so that planning never holds the
interpreter lock or the cores a stop's answer needs; the thread waits on its pipe). A
failure there (it ends, it fails) is that request's ``INTERNAL``; the next starts another.
Requests wait in a bounded backlog
(``planning.max_queue``; beyond it the answer is ``BUSY``). A station pair that the station
table holds never waits behind planning: the answering thread gives it at once (from a
queue of its own, as long). Every queued request is answered by ``planning.timeout``
seconds after its receipt: the watchdog thread answers ``TIMEOUT`` at that instant for one
not answered yet (waiting or still being planned), and a plan finished later is dropped,
never sent. Every answer published is kept for stop requests, which its ``stops``
answers on a thread of their own. The roadmap is loaded and rebuilt by the worker's loader
(``loader``: its own thread, the same lock); until a roadmap serves, every request is answered
``ROADMAP_NOT_READY`` at once, saying why. Each request is planned on the
roadmap in force when it was received, the one a recording pairs it with, and answered as
``service.planning`` says. The worker never
publishes: it hands every message, already serialised, to ``send``, which the node
publishes from its executor. Every request gets exactly one answer, whatever happens: a
failure of the node itself is answered ``INTERNAL`` with the reason. On stop the threads
are left as they are (daemons): the node never waits for a plan or the pair of the table
being planned.
"""

from collections import deque
import heapq
import threading
import time
from typing import Callable, Optional

from wafer_planner_ros import kernels, kernels_lookup
from wafer_planner_ros.cell.model import Cell
from wafer_planner_ros.errors import ErrorCode, PlanningError
from wafer_planner_ros.node import markers, messages
from wafer_planner_ros.node.faults import reason_of, SafeLogger
from wafer_planner_ros.node.loader import Phase, RoadmapLoader
from wafer_planner_ros.node.messages import Sent
from wafer_planner_ros.node.recording import NodeRecording
from wafer_planner_ros.node.serving import Serving, store_optima_files, table_counts
from wafer_planner_ros.node.stops import Stops
from wafer_planner_ros.service.planning_process import PlanningProcess
from wafer_planner_ros.service.requests import Moving
from wafer_planner_ros.service.settings import NodeSettings

PREVIOUS_KEPT_NS = 1_000_000_000
"""How long the previous roadmap is kept for requests received before a new one serves but
not yet queued (the executor hands them over within milliseconds)."""
NOT_LOADED = 'the roadmap is being loaded or built'
OPTIMA_STORED_EVERY = 60.0
"""s: the optima learnt from the answers (``planner.optima``) are stored at most this often
after an answer (by the planning process: tens of ms), and when the node stops."""
OPTIMA_STOP_TURN = 0.05
"""s: at stop, how long a plan under way is waited for before the optima are stored (else
they are not, and those learnt since the last time are lost: only speed)."""


class PlanningWorker:
    """The planning, answering and watchdog threads, their queues and the loader."""

    def __init__(self, settings: Callable[[], NodeSettings], recording: NodeRecording,
                 send: Callable, logger, stamp: Callable, serve_stops: Callable,
                 deliver: Callable):
        """
        Start the threads; the loader's first loads the roadmap.

        ``settings`` returns the node's current settings; ``send(*items)`` hands
        (kind, message, query number) items to the executor and never raises; ``stamp``
        returns a ROS time; ``serve_stops`` and ``deliver`` are the stop thread's way in
        and out (``Stops``).
        """
        self._settings, self._recording, self._send = settings, recording, send
        self._logger, self._stamp = SafeLogger(logger), stamp
        self.lock = threading.Condition()
        """
        Guards the queues, the open queries, the loader's roadmaps and load state, the station
        table and the counts; wakes the threads.

        ``cell`` and ``answer_error`` read the loader's ``serving`` without it: one reference,
        replaced whole under the lock, so a read sees the old roadmap or the new one, never half.
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
        self.counts = {'served': 0, 'failed': 0}
        self.last_error = ''
        self._optima_stored = time.monotonic()
        """When the planning process last stored its optima (``_store_optima``)."""
        self._answered = False
        """Whether a request was planned since (and so the optima may have grown)."""
        self.planning = PlanningProcess()
        """The child process planning what the station table does not hold."""
        try:
            self.planning.start()  # its imports beside the roadmap's load
        except RuntimeError as exc:  # the roadmap's hand-over tries again
            self._logger.error(f'the planning process did not start: {reason_of(exc)}')
        self._loader = RoadmapLoader(self.lock, settings, recording, send, self._logger, stamp,
                                     self._load_failed, self.planning)
        self.stops = Stops(serve_stops, deliver, self.answer_error, self.answer_internal,
                           self._logger, stamp, lambda: self._settings().stops_ahead_share)
        """The published trajectories and the stop requests' own thread (``stops``)."""
        self._threads = [threading.Thread(target=target, name=name, daemon=True) for name, target
                         in (('wafer_planner_worker', lambda: self._work(self._backlog)),
                             ('wafer_planner_table', lambda: self._work(self._lane)),
                             ('wafer_planner_watchdog', self._watch))]
        for thread in self._threads:
            thread.start()
        self._loader.start()

    @property
    def cell(self) -> Optional[Cell]:
        """Return the serving roadmap's cell, or before the first load the one it loads."""
        return self._loader.cell

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
                serving = self._loader.serving
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

        Return ``loader.STARTED``, ``loader.QUEUED`` or None (``RoadmapLoader.rebuild``).
        """
        return self._loader.rebuild()

    def answer_error(self, number, request_id, code, message, start, goal,
                     planning_ms=None, roadmap=None) -> None:
        """Send the error answer of query ``number``; never raise."""
        try:
            serving = self._loader.serving
            if roadmap is None and serving is not None:
                roadmap = serving.cached.roadmap
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
        loader = self._loader
        with self.lock:
            serving = loader.serving
            roadmap = serving.cached.roadmap if serving is not None else None
            cell = loader.cell
            return {
                'ready': serving is not None,
                'busy_with': loader.phase.value if loader.phase not in (
                    Phase.IDLE, Phase.STOPPING) else 'plan' if self._planned else None,
                'cell': cell.name if cell is not None else None,
                'nodes': roadmap.node_count if roadmap is not None else 0,
                'edges': roadmap.edge_count if roadmap is not None else 0,
                'hash': roadmap.digest if roadmap is not None else '',
                'seed': roadmap.seed if roadmap is not None else settings.seed,
                'queue': self._waiting(self._backlog),
                'served': self.counts['served'], 'failed': self.counts['failed'],
                'last_error': self.last_error,
                'rebuild_failed': loader.load_failed,
                'last_rebuild_error': loader.last_load_error,
                **table_counts(serving),
                'kernels_compiled': kernels.compiled_count(),
                'kernels_ahead': kernels_lookup.ahead_count(),
            }

    def request_stop(self) -> None:
        """Have the threads stop taking work (see ``join``)."""
        self._loader.enter(Phase.STOPPING)
        self.stops.stop()

    def join(self, timeout: float) -> None:
        """
        Wait up to ``timeout`` seconds in all for the threads to stop.

        A plan, a roadmap build or a station table being planned is not waited for beyond
        that: the threads are daemons, ended with the process; the planning process is
        ended then.
        """
        deadline = time.monotonic() + timeout
        for thread in self._threads + [self._loader.thread]:
            thread.join(max(0.0, deadline - time.monotonic()))
        self.stops.join(max(0.0, deadline - time.monotonic()))
        serving = self._loader.serving
        if serving is not None and self._answered:
            self._store_optima(serving, self._settings(), turn=OPTIMA_STOP_TURN)
        self.planning.close()

    def _store_optima(self, serving: Serving, settings, turn: Optional[float] = None) -> None:
        """
        Have the planning process store the optima it learnt (``serving.store_optima_files``).

        After an answer (``turn`` None): not within ``OPTIMA_STORED_EVERY`` s of the last
        time. ``turn``: at once, unless a plan under way has not ended within ``turn`` s.
        """
        now = time.monotonic()
        if turn is None and now - self._optima_stored < OPTIMA_STORED_EVERY:
            return
        self._optima_stored, self._answered = now, False
        try:
            store_optima_files(self.planning, serving.key, serving.planner, settings,
                               self._logger, turn)
        except Exception as exc:  # noqa: B902 - only requests near them are slower
            self._logger.error(f'optima not stored: {reason_of(exc)}')

    # ----------------------------------------------------------------- planning

    def _not_ready(self) -> str:
        """Return why the node cannot answer yet; call with the lock held."""
        loader = self._loader
        if loader.phase is Phase.COMPILING:
            return ('the planning kernels are being compiled for this machine (about 40 s; '
                    '`wafer-kernels` compiles them ahead)')
        if loader.load_failed and loader.phase is Phase.IDLE:
            return f'roadmap not loaded: {loader.last_load_error}'
        return NOT_LOADED

    def _work(self, queue: deque) -> None:
        """Answer the requests of ``queue`` one at a time until stopped."""
        while True:
            with self.lock:
                while not queue and self._loader.phase is not Phase.STOPPING:
                    self.lock.wait()
                if self._loader.phase is Phase.STOPPING:
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
                while not expired and self._loader.phase is not Phase.STOPPING:
                    now = time.monotonic()
                    while self._deadlines and self._deadlines[0][0] <= now:
                        number = heapq.heappop(self._deadlines)[1]
                        if number in self._open:
                            expired.append((number, self._open.pop(number),
                                            number in self._planned, len(self._planned)))
                    if not expired:
                        self.lock.wait(self._deadlines[0][0] - now if self._deadlines
                                       else None)
                if self._loader.phase is Phase.STOPPING:
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
        loader = self._loader
        while loader.pending_ns is not None and received_ns >= loader.pending_ns:
            self.lock.wait()  # recorded as taking over, not serving yet: a moment
        serving, previous = loader.serving, loader.previous
        if serving is not None and received_ns < serving.loaded_ns and previous is not None:
            return previous
        if previous is not None and serving is not None \
                and time.time_ns() - serving.loaded_ns > PREVIOUS_KEPT_NS \
                and all(item[3] >= serving.loaded_ns for queued in (self._backlog, self._lane)
                        for item in queued):
            loader.previous = None  # no request needs it any more: free its memory
        return serving

    def _plan(self, serving: Serving, number: int, request, received: float) -> None:
        """Answer a request on ``serving``, unless the watchdog has (the plan is then dropped)."""
        roadmap, begun, doing = None, None, 'planning'
        try:
            settings = self._settings()
            with self.lock:
                deadline = self._open.get(number, (None, received + settings.timeout))[1]
            service = self.planning.service(serving.key, serving.service.using(
                settings.optimise_budget, settings.sample_period))
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
                if isinstance(request.start, Moving):
                    result, stamp = self.stops.divert(service, request, deadline)
                else:
                    result, stamp = service.answer(request.start, request.goal, deadline,
                                                   request.load), None
            except PlanningError as exc:
                self._answer_error(number, request, exc.code, exc.message,
                                   (time.monotonic() - begun) * 1000.0, roadmap)
                return
            doing, stamp = 'answering', stamp or self._stamp()
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
        self.stops.keep(request.request_id, planner, result, roadmap, stamp)
        with self.lock:
            self.counts['served'] += 1
        try:
            path = markers.path_markers(planner.cell, result, settings.frame_id, stamp)
        except Exception as exc:  # noqa: B902 - answered already: only the picture is lost
            self._logger.error(f'request {request.request_id}: no path markers: {reason_of(exc)}')
            return
        self._send((Sent.PATH, path, number))
        self._answered = True
        self._store_optima(serving, settings)

    def _answer_error(self, number: int, request, code, message: str, planning_ms=None,
                      roadmap=None) -> None:
        """Send the error answer of a queued query, unless it was answered already."""
        if self._claim(number):
            self.answer_error(number, request.request_id, code, message, request.start,
                              request.goal, planning_ms, roadmap)

    def _load_failed(self, message: str) -> None:
        """Say why the load failed as the last error (the loader calls it with the lock held)."""
        self.last_error = message
