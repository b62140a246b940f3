"""
The planning node ``wafer_planner``: a thin ROS edge around the core.

Threads: a single-threaded executor (subscriptions, services, the diagnostics timer,
publishing: every callback is short), the worker's four (``worker``: one plans, one request
at a time; one answers the station pairs the table holds; a watchdog answers ``TIMEOUT`` at
every deadline; its loader's, ``loader``, loads or rebuilds the roadmap while the previous
one serves; the compiled kernels release the GIL), the stops' two (``stops``: one waits on
the stop requests' own subscription, on a node no executor spins, ``stop_requests``, and
answers them there; one makes stops ahead of the running move), the one loading the kernels
from the process's start (``startup``; with one more saying when they are being compiled,
if they must be), the recorder's (``node.recording``) and, with ``live.port`` set, the
Foxglove server's (``live``, ``live_server``). Requests are handed to the recording (which
writes each with its answers, a query whole in one file), read and checked in the
subscription callback, then handed to the worker. The worker hands every answer back
through a guard condition, so all its publishing happens on the executor; the stop thread
publishes its answers itself (``_deliver_now``), at once. Each answer is recorded before it
goes out (a stop's right after); each request gets exactly one ``~/result``, whatever
happens: no request, however malformed, and no failure while answering it ends the node (a
failure of the node's own is answered ``INTERNAL``). What ``/diagnostics`` says is
``health``'s; recording switched on and off, ``recording_switch``'s.
"""

from collections import deque
import itertools
import json
import logging
import os
import sys
import threading
import time
from typing import Optional

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.serialization import deserialize_message
from std_msgs.msg import String
from std_srvs.srv import SetBool, Trigger
from trajectory_msgs.msg import JointTrajectory
from visualization_msgs.msg import MarkerArray

try:  # in a standard ROS install; not among the PyPI wheels: then no static transform
    from tf2_msgs.msg import TFMessage
except ImportError:
    TFMessage = None

from wafer_planner_ros.errors import ErrorCode
from wafer_planner_ros.node import markers
from wafer_planner_ros.node.faults import guarded_service, reason_of, SafeLogger
from wafer_planner_ros.node.health import diagnostics
from wafer_planner_ros.node.live import LiveView
from wafer_planner_ros.node.live_robot import RobotRelay
from wafer_planner_ros.node.loader import QUEUED
from wafer_planner_ros.node.messages import Sent
from wafer_planner_ros.node.process import spin
from wafer_planner_ros.node.qos import LATCHED, RELIABLE
from wafer_planner_ros.node.recording import limits_of, NodeRecording
from wafer_planner_ros.node.recording_switch import RecordingSwitch
from wafer_planner_ros.node.startup import core_warnings_to, load_kernels
from wafer_planner_ros.node.stop_requests import StopRequests
from wafer_planner_ros.node.worker import PlanningWorker
from wafer_planner_ros.recording.bag import qos, Topic
from wafer_planner_ros.service.requests import request_id_of, request_of, RequestError
from wafer_planner_ros.service.requests import stop_request
from wafer_planner_ros.service.settings import check, PARAMETERS, settings_from

DELIVER_SLICE = 0.005
"""s of publishing (and recording) per executor turn: a burst's answers, each recorded
before it goes out, do not hold up ``~/get_status`` behind them."""
SWITCH_INTERVAL = 0.0002
"""s a thread waits for the interpreter lock before the one holding it must let it go
(``sys.setswitchinterval``; Python's default 5 ms). Planning holds it in Python stretches
between its compiled calls: every time the stop thread needs it back (woken by a request,
after publishing, ...) it waits up to this long. A stop while a joint request was planned,
end to end at p99: 10.3 ms at 1 ms, 8.8 ms at 0.2 ms (30 stops each); 10.8 ms over 240 at
0.2 ms, within the spread of the runs at 1 ms (10.7-11.6 ms; doc/benchmark.md)."""
STOP_WAIT = 0.2
"""s a stopping node waits for the worker's threads: idle ones end at once; a plan, a roadmap
build or a station table being planned ends with the process (they write only whole files)."""
# The QoS profiles, as the recording's channel metadata states them.
RELIABLE_OFFERED = qos(keep_all=True, depth=RELIABLE.depth)
LATCHED_OFFERED = qos(depth=1, transient_local=True)


class WaferPlannerNode(Node):
    """Plans wafer transfers on request; see the module's description."""

    def __init__(self, own_process: bool = False, **kwargs):
        """
        Declare and check the parameters, set up the interfaces, start the worker.

        ``own_process``: the node has the process to itself (``main``): the core's Python
        logging goes to the node's log.
        """
        super().__init__('wafer_planner', **kwargs)
        self.log = SafeLogger(self.get_logger())
        """The logger of the failure paths: it never raises."""
        if own_process:
            core_warnings_to(self.log)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        for spec in PARAMETERS:
            self.declare_parameter(spec.name, spec.default, _descriptor(spec))
        self.settings = settings_from(
            {spec.name: self.get_parameter(spec.name).value for spec in PARAMETERS})
        self._outbox_lock = threading.Lock()
        self._outbox = deque()
        self._trajectory_pub = self.create_publisher(JointTrajectory, '~/trajectory', RELIABLE)
        self._result_pub = self.create_publisher(DiagnosticStatus, '~/result', RELIABLE)
        self._roadmap_pub = self.create_publisher(MarkerArray, '~/roadmap_markers', LATCHED)
        self._path_pub = self.create_publisher(MarkerArray, '~/path_markers', RELIABLE)
        self._tf_pub = None if TFMessage is None else \
            self.create_publisher(TFMessage, '/tf_static', LATCHED)
        self._diagnostics_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self._live = LiveView(self.get_fully_qualified_name(), [
            self._roadmap_pub, self._path_pub, self._trajectory_pub, self._result_pub,
            self._diagnostics_pub], self._roadmap_pub, self.log)
        self._robot = RobotRelay(self, self._live)
        self._robot.follow(self.settings.live_robot, self.settings.live_port != 0)
        self._live.start(self.settings.live_host, self.settings.live_port,
                         self.settings.live_max_clients)
        # Raw: the request's bytes are recorded exactly as they arrived.
        self._joint_sub = self.create_subscription(
            JointTrajectory, '~/plan_request', self._on_joint_request, RELIABLE, raw=True)
        self._station_sub = self.create_subscription(
            String, '~/plan_station_request', self._on_station_request, RELIABLE, raw=True)
        # Stop requests on a node and thread of their own, answered there (``stops``).
        self._stop_requests = StopRequests(self, self._on_stop_request)
        self._numbers = itertools.count(1)
        self._late_records = 0
        self._recording = NodeRecording(self.get_name(), [
            Topic(self._joint_sub.topic_name, 'trajectory_msgs/msg/JointTrajectory',
                  RELIABLE_OFFERED),
            Topic(self._station_sub.topic_name, 'std_msgs/msg/String', RELIABLE_OFFERED),
            Topic(self._stop_requests.topic_name, 'std_msgs/msg/String', RELIABLE_OFFERED),
            Topic(self._trajectory_pub.topic_name, 'trajectory_msgs/msg/JointTrajectory',
                  RELIABLE_OFFERED),
            Topic(self._result_pub.topic_name, 'diagnostic_msgs/msg/DiagnosticStatus',
                  RELIABLE_OFFERED),
            Topic(self._roadmap_pub.topic_name, 'visualization_msgs/msg/MarkerArray',
                  LATCHED_OFFERED)], self._roadmap_pub.topic_name, self._recording_failed,
            lambda: limits_of(self.settings))
        self._switch = RecordingSwitch(self, self._recording)
        self._recording.parameters(self._parameter_values())
        if self.settings.recording_enabled:
            self._switch.start()
        self.create_service(Trigger, '~/get_status', self._on_get_status)
        self.create_service(Trigger, '~/rebuild_roadmap', self._on_rebuild)
        self.create_service(SetBool, '~/set_recording', self._on_set_recording)
        self._deliver = self.create_guard_condition(self._on_deliver)
        self.create_timer(1.0, self._publish_health)
        self._worker = PlanningWorker(lambda: self.settings, self._recording,
                                      lambda *items: self._send(*items), self.get_logger(),
                                      lambda: self.get_clock().now().to_msg(),
                                      self._stop_requests.serve, self._deliver_now)

    # ----------------------------------------------------------------- requests in

    def _on_joint_request(self, data: bytes, info) -> None:
        self._on_request('joint', self._joint_sub.topic_name, JointTrajectory, data, info)

    def _on_station_request(self, data: bytes, info) -> None:
        self._on_request('station', self._station_sub.topic_name, String, data, info)

    def _on_stop_request(self, data: bytes, info) -> None:
        # The stop thread's (``stop_requests``): the other threads give way meanwhile.
        self._on_request('stop', self._stop_requests.topic_name, String, data, info)

    def _on_request(self, kind: str, topic: str, message_type, data: bytes, info) -> None:
        try:
            self._take_request(kind, topic, message_type, data, info)
        except Exception as exc:  # noqa: B902 - the last resort: the node serves on
            self.log.error(f'a request on {topic} was lost: {reason_of(exc)}')

    def _take_request(self, kind: str, topic: str, message_type, data: bytes, info) -> None:
        """Record, read and check a request, then queue it: one answer, whatever happens."""
        received, number = time.monotonic(), next(self._numbers)
        received_ns = info.get('received_timestamp') or time.time_ns()  # as recorded
        try:
            self._recording.request(topic, data, number, info)
        except Exception as exc:  # noqa: B902 - planning goes on without recording
            self.log.error(f'request {number} not recorded: {reason_of(exc)}')
        request_id = ''
        try:
            try:
                msg = deserialize_message(data, message_type)
            except Exception as exc:  # noqa: B902 - bytes that are no such message
                raise RequestError(ErrorCode.INVALID_REQUEST,
                                   f'the request is not a {message_type.__name__} '
                                   f'({reason_of(exc)})') from None
            cell = self._worker.cell
            if kind == 'joint':
                request_id = request_id_of(msg.header.frame_id) if msg.header.frame_id else ''
                if cell is None:  # the joint names cannot be checked yet: not ready
                    self._worker.answer_error(number, request_id,
                                              ErrorCode.ROADMAP_NOT_READY,
                                              'not ready: the cell is being loaded', None, None)
                    return
            if kind == 'stop':
                # Answered here and now: this is the stop thread (``stop_requests``).
                self._worker.stops.answer(number, stop_request(msg.data), received)
                return
            request = request_of(kind, msg, cell.robot.joint_names if cell is not None else ())
        except RequestError as exc:
            self._worker.answer_error(number, exc.request_id, exc.code, exc.message, None,
                                      None)
            return
        except Exception as exc:  # noqa: B902 - every request gets its one answer
            self._worker.answer_internal(number, request_id, exc, 'reading the request')
            return
        self._worker.enqueue(number, request, received, received_ns)

    # ----------------------------------------------------------------- answers out

    def _send(self, *items) -> None:
        """Hand messages to the executor (publishing happens in ``_on_deliver``)."""
        with self._outbox_lock:
            self._outbox.extend(items)
        try:
            self._deliver.trigger()
        except Exception:  # noqa: B902 - only once the node is being destroyed
            pass

    def _on_deliver(self) -> None:
        """Publish what the worker handed over, for at most ``DELIVER_SLICE`` seconds a turn."""
        began = time.monotonic()
        while True:
            if time.monotonic() - began > DELIVER_SLICE:
                # The rest on the next turn: status queries and requests get theirs between.
                self._deliver.trigger()
                return
            with self._outbox_lock:
                if not self._outbox:
                    return
                kind, msg, number = self._outbox.popleft()
            try:
                self._deliver_one(kind, msg, number)
            except Exception as exc:  # noqa: B902 - the next answers still go out
                self.log.error(f'query {number}: {kind.name.lower()} not published: '
                               f'{reason_of(exc)}')

    def _deliver_now(self, kind: Sent, msg, number: int) -> None:
        """
        Publish one answer at once, in the calling thread (the stop thread's), then record it.

        A stop must not wait for a disk: unlike the worker's answers, it goes out first and
        is recorded right after (a crash in between loses that one record).
        """
        try:
            self._deliver_one(kind, msg, number, recorded_first=False)
        except Exception as exc:  # noqa: B902 - the next answers still go out
            self.log.error(f'query {number}: {kind.name.lower()} not published: '
                           f'{reason_of(exc)}')

    def _deliver_one(self, kind: Sent, msg, number: int, recorded_first: bool = True) -> None:
        if kind in (Sent.ANSWER, Sent.RESULT):
            # An answer is recorded, and safe from a crash, before it goes out (a stop's
            # right after: ``_deliver_now``). The trajectory before its result: a client
            # holding the result can rely on the trajectory having been sent.
            out = ((self._trajectory_pub, msg[0]), (self._result_pub, msg[1])) \
                if kind is Sent.ANSWER else ((self._result_pub, msg),)
            if recorded_first:
                self._record_answer(number, out)
            for publisher, data in out:
                publisher.publish(data)
                self._live.publish(publisher, data)
            if not recorded_first:
                self._record_answer(number, out, counted=False)
        else:
            publisher = self._roadmap_pub if kind is Sent.MARKERS else self._path_pub
            publisher.publish(msg)
            self._live.publish(publisher, msg)
            if kind is Sent.MARKERS:
                self._place_joint_space()

    def _record_answer(self, number: int, out, counted: bool = True) -> None:
        """
        Record query ``number`` with its answer ``out`` ((publisher, bytes) pairs).

        ``counted``: one recorded after it went out is counted in ``answers_before_recorded``
        (a stalled disk); False for a stop's, recorded after it by design.
        """
        try:
            recorded = self._recording.answer(number, [(p.topic_name, data) for p, data in out])
        except Exception as exc:  # noqa: B902 - the answer goes out all the same
            self.log.error(f'query {number}: answer not recorded: {reason_of(exc)}')
            recorded = False
        if recorded is False and counted:
            with self._outbox_lock:  # the executor's and the stop thread's
                self._late_records += 1

    def _place_joint_space(self) -> None:
        """Publish where the joint-space markers' frame stands beside the cell (static)."""
        parent = self.settings.frame_id
        child = markers.joint_space_frame(parent)
        offset = markers.joint_space_offset(self._worker.cell).tolist()
        self._live.frame(parent, child, offset)
        if self._tf_pub is None:
            return
        from geometry_msgs.msg import TransformStamped
        msg = TransformStamped(child_frame_id=child)
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.header.frame_id = parent
        t = msg.transform.translation
        t.x, t.y, t.z = offset
        self._tf_pub.publish(TFMessage(transforms=[msg]))

    # ----------------------------------------------------------------- services, health

    def status(self) -> dict:
        """Return the node's state (``~/get_status``)."""
        return {**self._worker.status(), **self._recording.status(),
                'answers_before_recorded': self._late_records, **self._live.status()}

    @guarded_service
    def _on_get_status(self, request, response):
        response.success = True
        response.message = json.dumps(self.status())
        return response

    @guarded_service
    def _on_rebuild(self, request, response):
        began = self._worker.rebuild()
        response.success = began is not None
        if began is None:
            response.message = 'the node is stopping'
        elif began == QUEUED:
            response.message = ('rebuild queued: it starts with the parameters then in force '
                                'once the load under way ends (a station table being planned '
                                'stops after its current pair); the current roadmap serves '
                                'until the new one does (~/get_status: busy_with "load" until '
                                'done, rebuild_failed if it failed)')
        else:
            response.message = ('rebuild started with the current parameters; the current '
                                'roadmap serves until the new one does (~/get_status: busy_with '
                                '"load" until done, rebuild_failed if it failed)')
        return response

    @guarded_service
    def _on_set_recording(self, request, response):
        response.success, response.message = self._switch.switch(request.data)
        return response

    def _recording_failed(self, message: str) -> None:
        self.get_logger().error(f'{message}; planning goes on without recording')

    def _parameter_values(self, changed: Optional[dict] = None) -> dict:
        values = {spec.name: self.get_parameter(spec.name).value for spec in PARAMETERS
                  if self.has_parameter(spec.name)}
        values.update(changed or {})
        return values

    def _publish_health(self) -> None:
        try:
            self._switch.sync_enabled()  # a recording that stopped by itself: false
            health = self._health()
            self._diagnostics_pub.publish(health)
            self._live.publish(self._diagnostics_pub, health)
        except Exception as exc:  # noqa: B902 - health is reported again in a second
            self.log.error(f'/diagnostics not published: {reason_of(exc)}')

    def _health(self) -> DiagnosticArray:
        array = diagnostics(self.status(), self.get_name())
        array.header.stamp = self.get_clock().now().to_msg()
        return array

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
            self.settings = settings  # read as a whole by the worker: no lock needed
            try:
                self._recording.parameters(self._parameter_values(changed))
                if 'recording.enabled' in changed:
                    self._switch.follow(settings.recording_enabled)
            except Exception as exc:  # noqa: B902 - the parameters are set all the same
                self.log.error(f'recording the parameters failed: {reason_of(exc)}')
            if any(name.startswith('live.') for name in changed):
                self._robot.follow(settings.live_robot, settings.live_port != 0)
                self._live.start(settings.live_host, settings.live_port,  # never raises
                                 settings.live_max_clients)
        return SetParametersResult(successful=True)

    def destroy_node(self) -> None:
        """Close the recording, stop the worker's threads (not waiting for a plan), destroy."""
        self._worker.request_stop()
        # First: answers not yet published are not recorded either, and a plan or a
        # station table being planned is not waited for (``STOP_WAIT``).
        self._switch.stop()
        self._live.stop()
        self._worker.join(timeout=STOP_WAIT)
        self._stop_requests.close()
        super().destroy_node()


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
    # The worker plans in Python: let the other threads in for the GIL every SWITCH_INTERVAL
    # (default 5 ms) so that stops, status queries and answers are not held up by planning.
    sys.setswitchinterval(SWITCH_INTERVAL)
    load_kernels()  # beside ROS's start and the roadmap's load
    return spin(lambda: WaferPlannerNode(own_process=True), 'wafer_planner', args)


def entry_point() -> None:
    """
    Console script ``wafer_planner_node``: run, then end the process at once.

    A plan, a roadmap build or a station table still running in the worker's threads is
    abandoned (the recording is closed, and every file the core writes is written whole:
    a temporary file, then a rename), not left to the interpreter's shutdown, where compiled
    code still running in a thread can abort the process.
    """
    code = main()
    logging.shutdown()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


if __name__ == '__main__':
    entry_point()
