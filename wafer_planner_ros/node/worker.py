"""
The node's planning worker: one thread, loading the roadmap and planning (SPEC section 5).

It loads or rebuilds the roadmap and plans one request at a time. Requests wait in a
bounded backlog (``planning.max_queue``; beyond it the answer is ``BUSY``). While the
roadmap loads or is rebuilt requests are answered ``ROADMAP_NOT_READY``; a request still
waiting ``planning.timeout`` seconds after its receipt is answered ``TIMEOUT``. The worker
never publishes: it hands every message, already serialised, to ``send``, which the node
publishes from its executor. Every request gets exactly one answer, whatever happens.
"""

from collections import deque
import gc
import threading
import time
from typing import Callable

from rclpy.serialization import serialize_message

from wafer_planner_ros.cache import load_or_build
from wafer_planner_ros.cell import Cell
from wafer_planner_ros.errors import ErrorCode, PlanningError, WaferPlannerError
from wafer_planner_ros.node import markers, messages
from wafer_planner_ros.node.recording import Loaded, NodeRecording
from wafer_planner_ros.node.settings import NodeSettings
from wafer_planner_ros.planner import Planner, PlannerSettings
from wafer_planner_ros.roadmap import RoadmapSettings


class PlanningWorker:
    """The loading and planning thread, its backlog and its state; see the module."""

    def __init__(self, settings: Callable[[], NodeSettings], recording: NodeRecording,
                 send: Callable, logger, stamp: Callable):
        """
        Start the thread, which first loads the roadmap.

        ``settings`` returns the node's current settings; ``send(*items)`` hands
        (kind, message, query number) items to the executor; ``stamp`` returns a ROS time.
        """
        self._settings, self._recording, self._send = settings, recording, send
        self._logger, self._stamp = logger, stamp
        self.lock = threading.Condition()
        """Guards everything below; ``notify`` wakes the thread."""
        self._backlog = deque([('load', None)])
        self.planner = None
        self.cell = None
        """The cell of the last load (set before its roadmap is ready)."""
        self.cached = None
        self.busy_with = None
        self.load_failed = False
        self.counts = {'served': 0, 'failed': 0}
        self.last_error = ''
        self._stopping = False
        self._thread = threading.Thread(target=self._work, name='wafer_planner_worker',
                                        daemon=True)
        self._thread.start()

    # ----------------------------------------------------------------- from the executor

    def enqueue(self, number: int, request, received: float) -> None:
        """Queue request ``number`` (received at ``received``, monotonic) or refuse it."""
        settings = self._settings()
        with self.lock:
            if self.planner is None:
                reason = self.last_error if self.load_failed else \
                    'the roadmap is being loaded or built'
                code, message = ErrorCode.ROADMAP_NOT_READY, f'not ready: {reason}'
            elif sum(1 for kind, _ in self._backlog if kind == 'plan') >= settings.max_queue:
                code = ErrorCode.BUSY
                message = (f'busy: {settings.max_queue} requests are already waiting '
                           '(planning.max_queue)')
            else:
                self._backlog.append(('plan', (number, request, received)))
                self.lock.notify()
                return
        self.answer_error(number, request.request_id, code, message, request.start,
                          request.goal)

    def rebuild(self) -> bool:
        """Queue a reload of the cell and roadmap; False when one is already under way."""
        with self.lock:
            if any(kind == 'load' for kind, _ in self._backlog) or self.busy_with == 'load':
                return False
            self.planner = None
            self._backlog.append(('load', None))
            self.lock.notify()
            return True

    def answer_error(self, number, request_id, code, message, start, goal,
                     planning_ms=None, roadmap=None) -> None:
        """Send the error answer of query ``number``."""
        if roadmap is None and self.cached is not None:
            roadmap = self.cached.roadmap
        self._logger.warning(f'request {request_id or "(no id)"}: {code.value}: {message}')
        status = messages.result_status(
            request_id, 'error', f'{code.value}: {message}',
            messages.error_values(code.value, roadmap, start, goal, planning_ms))
        with self.lock:
            self.counts['failed'] += 1
            self.last_error = f'{request_id}: {code.value}: {message}'
        self._send(('result', status, number))

    def status(self) -> dict:
        """Return the worker's part of ``~/get_status``."""
        with self.lock:
            roadmap = self.cached.roadmap if self.cached is not None else None
            return {
                'ready': self.planner is not None,
                'busy_with': self.busy_with,
                'cell': self.cell.name if self.cell is not None else None,
                'nodes': roadmap.node_count if roadmap is not None else 0,
                'edges': roadmap.edge_count if roadmap is not None else 0,
                'hash': roadmap.digest if roadmap is not None else '',
                'seed': roadmap.seed if roadmap is not None else self._settings().seed,
                'queue': sum(1 for kind, _ in self._backlog if kind == 'plan'),
                'served': self.counts['served'], 'failed': self.counts['failed'],
                'last_error': self.last_error,
            }

    def request_stop(self) -> None:
        """Have the thread stop after the request it is planning (see ``join``)."""
        with self.lock:
            self._stopping = True
            self.lock.notify_all()

    def join(self, timeout: float) -> None:
        """Wait up to ``timeout`` seconds for the thread to stop."""
        self._thread.join(timeout)

    # ----------------------------------------------------------------- the thread

    def _work(self) -> None:
        while True:
            with self.lock:
                while not self._backlog and not self._stopping:
                    self.lock.wait()
                if self._stopping:
                    return
                kind, item = self._backlog.popleft()
                self.busy_with = kind
            try:
                if kind == 'plan':
                    self._plan(*item)
                else:
                    self._load()
            finally:
                with self.lock:
                    self.busy_with = None

    def _load(self) -> None:
        """Load or build the roadmap for the current parameters; never raise."""
        with self.lock:
            self.planner = None
        settings = self._settings()
        started = time.monotonic()
        try:
            cell_text = settings.cell_file.read_bytes()  # the very text that is recorded
            cell = Cell.from_text(cell_text, str(settings.cell_file))
            self.cell = cell
            self._logger.info(f'cell {cell.name} from {settings.cell_file}; loading or '
                              f'building a roadmap of {settings.nodes} nodes')
            cached = load_or_build(cell, RoadmapSettings(nodes=settings.nodes), settings.seed,
                                   settings.cache_dir, self._progress())
            planner = Planner(cell, cached.roadmap,
                              PlannerSettings(sample_period=settings.sample_period))
            warm_up(planner)
        except Exception as exc:  # noqa: B902 - the node stays up and says why
            kind = '' if isinstance(exc, (WaferPlannerError, ValueError, OSError)) else \
                'internal error: '
            self.last_error = f'roadmap not loaded: {kind}{exc}'
            self._logger.error(self.last_error)
            with self.lock:
                self.cached, self.load_failed = None, True
            return
        roadmap = cached.roadmap
        # Everything loaded so far lives as long as the node: keep it out of the garbage
        # collector's full passes, which otherwise pause every thread for tens of ms.
        gc.collect()
        gc.freeze()
        # Recorded before it serves: every recorded query comes after the load it used.
        self._recording.loaded(Loaded(cell_text, {
            'cell': cell.name, 'cell_file': str(settings.cell_file),
            'cell_digest': cell.digest, 'roadmap_hash': roadmap.digest,
            'roadmap_nodes': str(settings.nodes), 'roadmap_seed': str(roadmap.seed),
            'roadmap_edges': str(roadmap.edge_count)}, time.time_ns()))
        with self.lock:
            self.cached, self.planner, self.load_failed = cached, planner, False
        roadmap_markers = serialize_message(markers.roadmap_markers(
            cell, roadmap, settings.frame_id, self._stamp()))
        self._send(('markers', roadmap_markers, 0))
        self._recording.markers(roadmap_markers)
        self._logger.info(
            f'ready: roadmap {roadmap.node_count} nodes, {roadmap.edge_count} edges, hash '
            f'{roadmap.digest[:12]}, {cached.status.value} in {cached.seconds:.2f} s '
            f'(ready {time.monotonic() - started:.2f} s after loading began)')

    def _progress(self):
        logger, last = self._logger, [-1]

        def report(done: int, total: int, edges: int) -> None:
            tenth = 10 * done // max(total, 1)
            if tenth != last[0]:
                last[0] = tenth
                logger.info(f'building roadmap: {done}/{total} nodes, {edges} edges')
        return report

    def _plan(self, number: int, request, received: float) -> None:
        settings = self._settings()
        with self.lock:
            planner, cached = self.planner, self.cached
        roadmap = cached.roadmap if cached is not None else None
        if planner is None:
            self.answer_error(number, request.request_id, ErrorCode.ROADMAP_NOT_READY,
                              'not ready: the roadmap is being rebuilt', request.start,
                              request.goal)
            return
        if planner.settings.sample_period != settings.sample_period:
            planner = Planner(planner.cell, planner.roadmap,
                              PlannerSettings(sample_period=settings.sample_period))
        begun = time.monotonic()
        try:
            result = planner.plan(request.start, request.goal,
                                  deadline=received + settings.timeout)
        except PlanningError as exc:
            self.answer_error(number, request.request_id, exc.code, exc.message, request.start,
                              request.goal, (time.monotonic() - begun) * 1000.0, roadmap)
            return
        except Exception as exc:  # noqa: B902 - every request gets its one answer
            self._logger.error(f'request {request.request_id}: internal error {exc!r}')
            self.answer_error(number, request.request_id, ErrorCode.INTERNAL,
                              f'internal error: {exc!r}', request.start, request.goal,
                              (time.monotonic() - begun) * 1000.0, roadmap)
            return
        stamp = self._stamp()
        level = 'warn' if result.warnings else 'ok'
        message = '; '.join(result.warnings) or (
            f'ok: {result.start.label} -> {result.goal.label} in {result.cycle_time:.3f} s')
        # The trajectory and its result go together (the node records both, then publishes
        # them); the markers, for people, after both.
        self._send(('answer', (
            messages.trajectory(result, request.request_id, planner.cell.robot.joint_names,
                                stamp),
            messages.result_status(
                request.request_id, level, message,
                dict(messages.plan_values(result, roadmap, request.start, request.goal),
                     node_ms=(time.monotonic() - received) * 1000.0))), number))
        self._send(('path', markers.path_markers(planner.cell, result, settings.frame_id,
                                                 stamp), number))
        with self.lock:
            self.counts['served'] += 1


def warm_up(planner) -> None:
    """Plan once so that the compiled kernels are loaded before the first request."""
    names = sorted(planner.cell.stations)
    try:
        planner.plan(names[0], names[-1])
    except (PlanningError, IndexError):
        pass  # a cell whose first and last stations cannot be joined still warms up
