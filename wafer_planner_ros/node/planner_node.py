"""
The planning node ``wafer_planner`` (SPEC section 5): a thin ROS edge around the core.

Threads: a single-threaded executor (subscriptions, services, the diagnostics timer,
publishing: every callback is short) and one worker that loads or rebuilds the roadmap and
plans, one request at a time; the compiled kernels release the GIL. Requests
are read and checked in the subscription callback, then wait in a bounded backlog
(``planning.max_queue``; beyond it the answer is ``BUSY``). While the roadmap loads or is
rebuilt new requests are answered ``ROADMAP_NOT_READY``; a request still waiting
``planning.timeout`` seconds after its receipt is answered ``TIMEOUT``. The worker hands
every answer back to the executor through a guard condition, so all publishing happens on
the executor; each request gets exactly one ``~/result``, whatever happens.
"""

from collections import deque
import gc
import itertools
import json
import sys
import threading
import time
from typing import Optional

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rcl_interfaces.msg import SetParametersResult
import rclpy
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import String
from std_srvs.srv import SetBool, Trigger
from trajectory_msgs.msg import JointTrajectory
from visualization_msgs.msg import MarkerArray

from wafer_planner_ros.cache import load_or_build
from wafer_planner_ros.cell import Cell
from wafer_planner_ros.errors import ErrorCode, PlanningError, WaferPlannerError
from wafer_planner_ros.node import markers, messages
from wafer_planner_ros.node.recording import Loaded, NodeRecording
from wafer_planner_ros.node.requests import request_of, RequestError
from wafer_planner_ros.node.settings import check, PARAMETERS, settings_from
from wafer_planner_ros.planner import Planner, PlannerSettings
from wafer_planner_ros.recording.bag import qos, Topic
from wafer_planner_ros.roadmap import RoadmapSettings

# Requests and answers: reliable and keep-all, so that a burst is delivered whole (a
# keep-last reader cache drops the oldest samples of a burst longer than its depth).
RELIABLE = QoSProfile(depth=1000, history=HistoryPolicy.KEEP_ALL,
                      reliability=ReliabilityPolicy.RELIABLE)
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
# The QoS profiles, as the recording's channel metadata states them.
RELIABLE_OFFERED = qos(keep_all=True, depth=RELIABLE.depth)
LATCHED_OFFERED = qos(depth=1, transient_local=True)


class WaferPlannerNode(Node):
    """Plans wafer transfers on request; see the module's description."""

    def __init__(self, **kwargs):
        """Declare and check the parameters, set up the interfaces, start the worker."""
        super().__init__('wafer_planner', **kwargs)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        for spec in PARAMETERS:
            self.declare_parameter(spec.name, spec.default, _descriptor(spec))
        self.settings = settings_from(
            {spec.name: self.get_parameter(spec.name).value for spec in PARAMETERS})
        self._lock = threading.Condition()
        self._backlog = deque()
        self._outbox = deque()
        self._planner = None
        self._cell = None
        self._cached = None
        self._busy_with = None
        self._load_failed = False
        self._counts = {'served': 0, 'failed': 0}
        self._last_error = ''
        self._stopping = False
        self._trajectory_pub = self.create_publisher(JointTrajectory, '~/trajectory', RELIABLE)
        self._result_pub = self.create_publisher(DiagnosticStatus, '~/result', RELIABLE)
        self._roadmap_pub = self.create_publisher(MarkerArray, '~/roadmap_markers', LATCHED)
        self._path_pub = self.create_publisher(MarkerArray, '~/path_markers', RELIABLE)
        self._diagnostics_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        # Raw: the request's bytes are recorded exactly as they arrived.
        self._joint_sub = self.create_subscription(
            JointTrajectory, '~/plan_request', self._on_joint_request, RELIABLE, raw=True)
        self._station_sub = self.create_subscription(
            String, '~/plan_station_request', self._on_station_request, RELIABLE, raw=True)
        self._numbers = itertools.count(1)
        self._late_records = 0
        self._switching_recording = False
        self._recording = NodeRecording(self.get_name(), [
            Topic(self._joint_sub.topic_name, 'trajectory_msgs/msg/JointTrajectory',
                  RELIABLE_OFFERED),
            Topic(self._station_sub.topic_name, 'std_msgs/msg/String', RELIABLE_OFFERED),
            Topic(self._trajectory_pub.topic_name, 'trajectory_msgs/msg/JointTrajectory',
                  RELIABLE_OFFERED),
            Topic(self._result_pub.topic_name, 'diagnostic_msgs/msg/DiagnosticStatus',
                  RELIABLE_OFFERED),
            Topic(self._roadmap_pub.topic_name, 'visualization_msgs/msg/MarkerArray',
                  LATCHED_OFFERED)], self._roadmap_pub.topic_name, self._recording_failed)
        self._recording.parameters(self._parameter_values())
        if self.settings.recording_enabled:
            self._start_recording()
        self.create_service(Trigger, '~/get_status', self._on_get_status)
        self.create_service(Trigger, '~/rebuild_roadmap', self._on_rebuild)
        self.create_service(SetBool, '~/set_recording', self._on_set_recording)
        self._deliver = self.create_guard_condition(self._on_deliver)
        self.create_timer(1.0, self._publish_health)
        self._worker = threading.Thread(target=self._work, name='wafer_planner_worker',
                                        daemon=True)
        self._backlog.append(('load', None))
        self._worker.start()

    # ----------------------------------------------------------------- requests in

    def _on_joint_request(self, data: bytes, info) -> None:
        received, number = time.monotonic(), next(self._numbers)
        self._recording.request(self._joint_sub.topic_name, data, number, info)
        msg = deserialize_message(data, JointTrajectory)
        cell = self._cell
        if cell is None:  # the joint names cannot be checked yet: not ready, as documented
            self._answer_error(number, msg.header.frame_id, ErrorCode.ROADMAP_NOT_READY,
                               'not ready: the cell is being loaded', None, None)
            return
        try:
            request = request_of('joint', msg, cell.robot.joint_names)
        except RequestError as exc:
            self._answer_error(number, exc.request_id, exc.code, exc.message, None, None)
            return
        self._enqueue(number, request, received)

    def _on_station_request(self, data: bytes, info) -> None:
        received, number = time.monotonic(), next(self._numbers)
        self._recording.request(self._station_sub.topic_name, data, number, info)
        try:
            request = request_of('station', deserialize_message(data, String), ())
        except RequestError as exc:
            self._answer_error(number, exc.request_id, exc.code, exc.message, None, None)
            return
        self._enqueue(number, request, received)

    def _enqueue(self, number: int, request, received: float) -> None:
        with self._lock:
            if self._planner is None:
                reason = self._last_error if self._load_failed else \
                    'the roadmap is being loaded or built'
                code, message = ErrorCode.ROADMAP_NOT_READY, f'not ready: {reason}'
            elif sum(1 for kind, _ in self._backlog if kind == 'plan') \
                    >= self.settings.max_queue:
                code = ErrorCode.BUSY
                message = (f'busy: {self.settings.max_queue} requests are already waiting '
                           '(planning.max_queue)')
            else:
                self._backlog.append(('plan', (number, request, received)))
                self._lock.notify()
                return
        self._answer_error(number, request.request_id, code, message, request.start,
                           request.goal)

    # ----------------------------------------------------------------- the worker

    def _work(self) -> None:
        while True:
            with self._lock:
                while not self._backlog and not self._stopping:
                    self._lock.wait()
                if self._stopping:
                    return
                kind, item = self._backlog.popleft()
                self._busy_with = kind
            try:
                if kind == 'plan':
                    self._plan(*item)
                else:
                    self._load()
            finally:
                with self._lock:
                    self._busy_with = None

    def _load(self) -> None:
        """Load or build the roadmap for the current parameters; never raise."""
        with self._lock:
            self._planner = None
            settings = self.settings
        started = time.monotonic()
        try:
            cell_text = settings.cell_file.read_bytes()  # the very text that is recorded
            cell = Cell.from_text(cell_text, str(settings.cell_file))
            self._cell = cell
            self.get_logger().info(f'cell {cell.name} from {settings.cell_file}; loading or '
                                   f'building a roadmap of {settings.nodes} nodes')
            cached = load_or_build(cell, RoadmapSettings(nodes=settings.nodes), settings.seed,
                                   settings.cache_dir, self._progress())
            planner = Planner(cell, cached.roadmap,
                              PlannerSettings(sample_period=settings.sample_period))
            _warm_up(planner)
        except Exception as exc:  # noqa: B902 - the node stays up and says why
            kind = '' if isinstance(exc, (WaferPlannerError, ValueError, OSError)) else \
                'internal error: '
            self._last_error = f'roadmap not loaded: {kind}{exc}'
            self.get_logger().error(self._last_error)
            with self._lock:
                self._cached, self._load_failed = None, True
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
        with self._lock:
            self._cached, self._planner, self._load_failed = cached, planner, False
        roadmap_markers = serialize_message(markers.roadmap_markers(
            cell, roadmap, settings.frame_id, self.get_clock().now().to_msg()))
        self._send(('markers', roadmap_markers, 0))
        self._recording.markers(roadmap_markers)
        self.get_logger().info(
            f'ready: roadmap {roadmap.node_count} nodes, {roadmap.edge_count} edges, hash '
            f'{roadmap.digest[:12]}, {cached.status.value} in {cached.seconds:.2f} s '
            f'(ready {time.monotonic() - started:.2f} s after loading began)')

    def _progress(self):
        logger, last = self.get_logger(), [-1]

        def report(done: int, total: int, edges: int) -> None:
            tenth = 10 * done // max(total, 1)
            if tenth != last[0]:
                last[0] = tenth
                logger.info(f'building roadmap: {done}/{total} nodes, {edges} edges')
        return report

    def _plan(self, number: int, request, received: float) -> None:
        with self._lock:
            planner, cached, settings = self._planner, self._cached, self.settings
        roadmap = cached.roadmap if cached is not None else None
        if planner is None:
            self._answer_error(number, request.request_id, ErrorCode.ROADMAP_NOT_READY,
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
            self._answer_error(number, request.request_id, exc.code, exc.message, request.start,
                               request.goal, (time.monotonic() - begun) * 1000.0, roadmap)
            return
        except Exception as exc:  # noqa: B902 - every request gets its one answer
            self.get_logger().error(f'request {request.request_id}: internal error {exc!r}')
            self._answer_error(number, request.request_id, ErrorCode.INTERNAL,
                               f'internal error: {exc!r}', request.start, request.goal,
                               (time.monotonic() - begun) * 1000.0, roadmap)
            return
        stamp = self.get_clock().now().to_msg()
        level = 'warn' if result.warnings else 'ok'
        message = '; '.join(result.warnings) or (
            f'ok: {result.start.label} -> {result.goal.label} in {result.cycle_time:.3f} s')
        # The trajectory and its result go together (see _on_deliver); the markers, for
        # people, after both.
        self._send(('answer', (
            messages.trajectory(result, request.request_id, planner.cell.robot.joint_names,
                                stamp),
            messages.result_status(
                request.request_id, level, message,
                dict(messages.plan_values(result, roadmap, request.start, request.goal),
                     node_ms=(time.monotonic() - received) * 1000.0))), number))
        self._send(('path', markers.path_markers(planner.cell, result, settings.frame_id,
                                                 stamp), number))
        with self._lock:
            self._counts['served'] += 1

    # ----------------------------------------------------------------- answers out

    def _answer_error(self, number, request_id, code, message, start, goal,
                      planning_ms=None, roadmap=None) -> None:
        if roadmap is None and self._cached is not None:
            roadmap = self._cached.roadmap
        self.get_logger().warning(f'request {request_id or "(no id)"}: {code.value}: {message}')
        status = messages.result_status(
            request_id, 'error', f'{code.value}: {message}',
            messages.error_values(code.value, roadmap, start, goal, planning_ms))
        with self._lock:
            self._counts['failed'] += 1
            self._last_error = f'{request_id}: {code.value}: {message}'
        self._send(('result', status, number))

    def _send(self, *items) -> None:
        """Hand messages to the executor (publishing happens in ``_on_deliver``)."""
        with self._lock:
            self._outbox.extend(items)
        self._deliver.trigger()

    def _on_deliver(self) -> None:
        while True:
            with self._lock:
                if not self._outbox:
                    return
                kind, msg, number = self._outbox.popleft()
            if kind in ('answer', 'result'):
                # An answer is recorded, and safe from a crash, before it goes out. The
                # trajectory before its result: a client holding the result can rely on
                # the trajectory having been sent.
                out = ((self._trajectory_pub, msg[0]), (self._result_pub, msg[1])) \
                    if kind == 'answer' else ((self._result_pub, msg),)
                if self._recording.answer(number, [(p.topic_name, data)
                                                   for p, data in out]) is False:
                    self._late_records += 1
                for publisher, data in out:
                    publisher.publish(data)
            else:
                (self._roadmap_pub if kind == 'markers' else self._path_pub).publish(msg)

    # ----------------------------------------------------------------- services, health

    def status(self) -> dict:
        """Return the node's state (``~/get_status``)."""
        with self._lock:
            roadmap = self._cached.roadmap if self._cached is not None else None
            return {
                'ready': self._planner is not None,
                'busy_with': self._busy_with,
                'cell': self._cell.name if self._cell is not None else None,
                'nodes': roadmap.node_count if roadmap is not None else 0,
                'edges': roadmap.edge_count if roadmap is not None else 0,
                'hash': roadmap.digest if roadmap is not None else '',
                'seed': roadmap.seed if roadmap is not None else self.settings.seed,
                'queue': sum(1 for kind, _ in self._backlog if kind == 'plan'),
                'served': self._counts['served'], 'failed': self._counts['failed'],
                'last_error': self._last_error,
                **self._recording.status(),
                'answers_before_recorded': self._late_records,
            }

    def _on_get_status(self, request, response):
        response.success = True
        response.message = json.dumps(self.status())
        return response

    def _on_rebuild(self, request, response):
        with self._lock:
            if any(kind == 'load' for kind, _ in self._backlog) or \
                    self._busy_with == 'load':
                response.success = False
                response.message = 'a roadmap load or rebuild is already under way'
                return response
            self._planner = None
            self._backlog.append(('load', None))
            self._lock.notify()
        response.success = True
        response.message = ('rebuild started with the current parameters; ~/get_status '
                            'reports ready when it is done')
        return response

    def _on_set_recording(self, request, response):
        if request.data:
            response.success = self._start_recording()
            response.message = (f'recording to {self._recording.last_directory}'
                                if response.success else self._recording.last_error)
        else:
            response.success, response.message = self._stop_recording()
            self._log_closed(response.success, response.message)
        # Keep recording.enabled telling the truth (without switching a second time).
        self._switching_recording = True
        try:
            self.set_parameters([Parameter('recording.enabled', value=bool(request.data))])
        finally:
            self._switching_recording = False
        return response

    def _log_closed(self, success: bool, message: str) -> None:
        if message == 'not recording':
            return
        if not self.context.ok():  # after Ctrl-C or SIGTERM the logger cannot reach /rosout
            print(f'[wafer_planner] {message}', file=sys.stderr, flush=True)
        elif success:
            self.get_logger().info(message)
        else:
            self.get_logger().error(message)

    def _stop_recording(self) -> tuple:
        """Close the recording; return (closed properly, a sentence saying so)."""
        directory, error = self._recording.stop()
        if directory is None:
            return True, 'not recording'
        if error:
            return False, f'recording {directory} not closed properly: {error}'
        return True, f'recording closed: {directory}'

    def _start_recording(self) -> bool:
        with self._lock:
            parent = self.settings.recording_directory
        try:
            directory = self._recording.start(parent)
        except OSError as exc:
            self.get_logger().error(f'{exc}; planning goes on without recording')
            return False
        self.get_logger().info(f'recording to {directory}')
        return True

    def _recording_failed(self, message: str) -> None:
        self.get_logger().error(f'{message}; planning goes on without recording')

    def _parameter_values(self, changed: Optional[dict] = None) -> dict:
        values = {spec.name: self.get_parameter(spec.name).value for spec in PARAMETERS
                  if self.has_parameter(spec.name)}
        values.update(changed or {})
        return values

    def _publish_health(self) -> None:
        status = self.status()
        level = DiagnosticStatus.OK if status['ready'] else DiagnosticStatus.WARN
        if not status['ready'] and status['busy_with'] is None:
            level = DiagnosticStatus.ERROR
        message = 'ready' if status['ready'] else (
            'loading the roadmap' if status['busy_with'] else status['last_error'])
        if status['recording_error']:
            level = max(level, DiagnosticStatus.WARN)
            message += f"; {status['recording_error']}"
        elif status.get('recording_stalled'):
            level = max(level, DiagnosticStatus.WARN)
            message += ('; recording stalled: the disk has not synced for 0.25 s, answers go '
                        'out before they are on it')
        keys = ('ready', 'nodes', 'edges', 'queue', 'served', 'failed', 'recording',
                'recording_directory', 'recording_error', 'answers_before_recorded')
        health = DiagnosticStatus(level=level, name=f'{self.get_name()}: health',
                                  message=message, hardware_id='wafer_planner',
                                  values=[KeyValue(key=k, value=str(status[k])) for k in keys])
        array = DiagnosticArray(status=[health])
        array.header.stamp = self.get_clock().now().to_msg()
        self._diagnostics_pub.publish(array)

    def _on_set_parameters(self, parameters) -> SetParametersResult:
        try:
            for parameter in parameters:
                check(parameter.name, parameter.value)
            changed = {p.name: p.value for p in parameters}
            current = {spec.name: self.get_parameter(spec.name).value for spec in PARAMETERS
                       if self.has_parameter(spec.name) and spec.name not in changed}
            settings = settings_from({**current, **changed})
        except ValueError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        if hasattr(self, '_recording'):  # not while the parameters are being declared
            with self._lock:
                self.settings = settings
            self._recording.parameters(self._parameter_values(changed))
            if 'recording.enabled' in changed and not self._switching_recording:
                if settings.recording_enabled:
                    self._start_recording()
                else:
                    self._log_closed(*self._stop_recording())
        return SetParametersResult(successful=True)

    def destroy_node(self) -> None:
        """Close the recording, stop the worker (after its request), destroy the node."""
        with self._lock:
            self._stopping = True
            self._lock.notify_all()
        # First: a worker busy building a roadmap may outlast a launcher's patience, and
        # answers not yet published are not recorded either.
        self._log_closed(*self._stop_recording())
        self._worker.join(timeout=30.0)
        super().destroy_node()


def _warm_up(planner) -> None:
    """Plan once so that the compiled kernels are loaded before the first request."""
    names = sorted(planner.cell.stations)
    try:
        planner.plan(names[0], names[-1])
    except (PlanningError, IndexError):
        pass  # a cell whose first and last stations cannot be joined still warms up


def _descriptor(spec) -> ParameterDescriptor:
    descriptor = ParameterDescriptor(description=spec.description)
    if spec.low is not None and isinstance(spec.default, int):
        descriptor.integer_range = [IntegerRange(from_value=int(spec.low),
                                                 to_value=int(spec.high), step=0)]
    elif spec.low is not None:
        descriptor.floating_point_range = [FloatingPointRange(from_value=float(spec.low),
                                                              to_value=float(spec.high),
                                                              step=0.0)]
    return descriptor


def main(args=None) -> int:
    """Run the node until interrupted (Ctrl-C or SIGTERM)."""
    # The worker plans in Python: let the executor's threads in for the GIL every 1 ms
    # (default 5 ms) so that status queries and answers are not held up by planning.
    sys.setswitchinterval(0.001)
    rclpy.init(args=args)
    node, executor, code = None, None, 0
    try:
        node = WaferPlannerNode()
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except (ValueError, ParameterException) as exc:
        print(f'wafer_planner: bad parameter: {exc}', flush=True)
        code = 2
    finally:
        if executor is not None:
            executor.shutdown()
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return code


def entry_point() -> None:
    """Console script ``wafer_planner_node``."""
    raise SystemExit(main())


if __name__ == '__main__':
    entry_point()
