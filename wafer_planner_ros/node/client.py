"""
Talking to a running planner node: finding it, waiting until it is ready, asking it.

``PlannerPeer`` is what ``wafer-plan-client`` (``ask_planner``) and ``wafer-replay
--publish`` share: the node's answers in order, and ``wait_ready``, which raises
``NoPlannerNode`` when discovery has not found the node within ``DISCOVERY`` seconds (a
node that is there but still loading is waited for, up to the caller's deadline).
"""

import json
import os
import time
from typing import Callable, Optional

from diagnostic_msgs.msg import DiagnosticStatus
import rclpy
from rclpy.node import Node
from std_msgs.msg import String
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory

from wafer_planner_ros.errors import WaferPlannerError
from wafer_planner_ros.node.qos import RELIABLE

DISCOVERY = 10.0
"""s within which discovery finds a running node on the same domain (a small part of this
on an idle machine's loopback; the margin is for a loaded one)."""


class NoPlannerNode(WaferPlannerError):
    """No node of that name was found."""

    def __init__(self, planner: str):
        """Say which node, and what to check."""
        super().__init__(
            f'no node {planner} found within {DISCOVERY:g} s (is it running, with the same '
            f"ROS_DOMAIN_ID ({os.environ.get('ROS_DOMAIN_ID', '0')} here) and "
            'ROS_AUTOMATIC_DISCOVERY_RANGE?)')


class PlannerPeer(Node):
    """A node that talks to a planner node: its answers, and waiting until it is ready."""

    def __init__(self, name: str, planner: str):
        """Subscribe to ``<planner>/result``; keep the answers in ``answers``, in order."""
        super().__init__(name)
        self.planner = planner
        self.answers = []
        self.create_subscription(DiagnosticStatus, f'{planner}/result', self.answers.append,
                                 RELIABLE)
        self.status = self.create_client(Trigger, f'{planner}/get_status')

    def wait_ready(self, deadline: float, publishers,
                   say: Callable[[str], None] = lambda text: None) -> bool:
        """
        Spin until the planner is ready and hears ``publishers``; False after ``deadline``.

        Raise ``NoPlannerNode`` when it is not found within ``DISCOVERY`` seconds; ``say``
        is told once what a node that is found but not ready is doing.
        """
        found_by = time.monotonic() + DISCOVERY
        told = False
        while True:
            status = self.planner_status()
            if status.get('ready') and all(p.get_subscription_count() for p in publishers) \
                    and self.count_publishers(f'{self.planner}/result'):
                return True
            if not status and time.monotonic() > found_by and not self._found():
                raise NoPlannerNode(self.planner)
            if status and not status.get('ready') and not told:
                say(f"waiting for {self.planner}: {status.get('busy_with') or 'not ready'} "
                    f"({status.get('last_rebuild_error') or 'loading the roadmap'})")
                told = True
            if time.monotonic() > deadline:
                return False
            rclpy.spin_once(self, timeout_sec=0.1)

    def planner_status(self) -> dict:
        """Return the planner's ``~/get_status`` ({} when it does not answer in 2 s)."""
        if not self.status.service_is_ready():
            return {}
        future = self.status.call_async(Trigger.Request())
        rclpy.spin_until_future_complete(self, future, timeout_sec=2.0)
        try:
            return json.loads(future.result().message) if future.done() else {}
        except ValueError:
            return {}

    def _found(self) -> bool:
        """Return whether discovery knows the planner: its node, its status service or result."""
        return self.status.service_is_ready() \
            or self.count_publishers(f'{self.planner}/result') > 0 \
            or any(f"{namespace.rstrip('/')}/{name}" == self.planner
                   for name, namespace in self.get_node_names_and_namespaces())


STOP_LEAD = 0.25
"""s before the moment it stops at that ``ask_planner`` sends a stop request: a stop is
planned in tens of milliseconds, and a controller given it after its moment would pick it
up from where the stop should be by then (a lurch)."""
DIVERT_LEAD = 1.0
"""s before the moment it leaves the move at that ``ask_planner`` sends a divert: the move
from where the stop rests is planned too, in hundreds of milliseconds, and the one curve
from the moving state for up to half a second more."""


def ask_planner(planner: str, request: dict, timeout: float,
                say: Callable[[str], None] = lambda text: None,
                stop_after: Optional[float] = None,
                divert_to: Optional[str] = None) -> Optional[tuple]:
    """
    Return (result, trajectory or None) of a station request to ``planner``.

    None when no answer came within ``timeout`` seconds (or on Ctrl-C); raise
    ``NoPlannerNode`` when the node is not found. ``stop_after``: then send a stop request
    of the trajectory at ``stop_after`` seconds after its start (its ``header.stamp``), id
    the request's with ``-stop``, ``STOP_LEAD`` before that moment (at once if it is
    sooner), so that its answer reaches the robot before it, and return (result,
    trajectory, stop result, stop trajectory); the stop's answer is waited for up to
    ``timeout`` seconds more. ``divert_to``: a station; instead of the stop, a station
    request from the trajectory at ``stop_after`` (default: half-way) to it, id the
    request's with ``-divert``, ``DIVERT_LEAD`` before that moment.
    """
    rclpy.init()
    try:
        client = _Client(planner)
        try:
            answer = client.ask(request, timeout, say)
            if answer is None or (stop_after is None and divert_to is None) \
                    or answer[1] is None:
                return answer
            sent = answer[1]
            if stop_after is None:
                last = sent.points[-1].time_from_start
                stop_after = 0.5 * (last.sec + 1e-9 * last.nanosec)
            if divert_to is None:
                then = {'id': f"{request['id']}-stop", 'trajectory': request['id'],
                        'at': stop_after}
                publisher, lead = client.stops, STOP_LEAD
            else:
                then = {'id': f"{request['id']}-divert", 'to': divert_to,
                        'from': {'trajectory': request['id'], 'at': stop_after},
                        **({'load': request['load']} if 'load' in request else {})}
                publisher, lead = client.requests, DIVERT_LEAD
            stamp = sent.header.stamp
            time.sleep(max(0.0, stamp.sec + 1e-9 * stamp.nanosec + stop_after - lead
                           - time.time()))
            followed = client.ask(then, timeout, say, publisher)
            return answer + ((None, None) if followed is None else followed)
        finally:
            client.destroy_node()
    except KeyboardInterrupt:
        return None
    finally:
        rclpy.try_shutdown()


class _Client(PlannerPeer):
    def __init__(self, planner: str):
        super().__init__(f'wafer_plan_client_{os.getpid()}', planner)
        self.trajectories = {}
        self.create_subscription(JointTrajectory, f'{planner}/trajectory',
                                 lambda m: self.trajectories.setdefault(m.header.frame_id, m),
                                 RELIABLE)
        self.requests = self.create_publisher(String, f'{planner}/plan_station_request',
                                              RELIABLE)
        self.stops = self.create_publisher(String, f'{planner}/stop_request', RELIABLE)

    def ask(self, request: dict, timeout: float, say: Callable[[str], None] = lambda t: None,
            publisher=None):
        """
        Return (result, trajectory or None) for the request, or None after ``timeout``.

        ``publisher``: where the request goes (default: the station requests).
        """
        deadline = time.monotonic() + timeout
        publisher = publisher or self.requests
        if not self.wait_ready(deadline, [publisher], say):
            return None
        publisher.publish(String(data=json.dumps(request)))
        rid = request['id']
        while (result := self._answer(rid)) is None:
            if time.monotonic() > deadline:
                return None
            rclpy.spin_once(self, timeout_sec=0.05)
        ok = result.level in (DiagnosticStatus.OK, DiagnosticStatus.WARN)
        while ok and rid not in self.trajectories and time.monotonic() < deadline:
            rclpy.spin_once(self, timeout_sec=0.05)
        return result, self.trajectories.get(rid)

    def _answer(self, request_id: str):
        return next((m for m in self.answers if m.name == request_id), None)
