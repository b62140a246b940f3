"""An in-process planner node with a private context, and a peer that talks to it."""

import json
import os
import sys
import tempfile
import threading
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
import rclpy
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from std_msgs.msg import String
from std_srvs.srv import SetBool, Trigger
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
from visualization_msgs.msg import MarkerArray

from wafer_planner_ros.node.planner_node import WaferPlannerNode
from wafer_planner_ros.node.qos import LATCHED, RELIABLE

RESEND = 5.0
"""Seconds a service call waits for its answer before it is sent again."""


def isolate_dds(tmp_path) -> None:
    """Keep DDS traffic on loopback, in a domain of this test run, logs in a temp dir."""
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    os.environ.setdefault('ROS_DOMAIN_ID', str(10 + os.getpid() % 80))
    os.environ['ROS_LOG_DIR'] = str(tmp_path / 'ros_log')


class Peer:
    """A node that talks to ``/wafer_planner`` from an executor thread of its own."""

    def __init__(self, context, nodes=()):
        """Spin a peer (and ``nodes``) on ``context``; wait until the node's topics match."""
        self.context = context
        self.peer = Node('test_peer', context=self.context)
        self.results, self.trajectories, self.roadmap_markers = [], [], []
        self.diagnostics = []
        self.peer.create_subscription(DiagnosticArray, '/diagnostics', self.diagnostics.append,
                                      10)
        self.peer.create_subscription(DiagnosticStatus, '/wafer_planner/result',
                                      self.results.append, RELIABLE)
        self.peer.create_subscription(JointTrajectory, '/wafer_planner/trajectory',
                                      self.trajectories.append, RELIABLE)
        self.joint_pub = self.peer.create_publisher(JointTrajectory,
                                                    '/wafer_planner/plan_request', RELIABLE)
        self.station_pub = self.peer.create_publisher(
            String, '/wafer_planner/plan_station_request', RELIABLE)
        self.stop_pub = self.peer.create_publisher(String, '/wafer_planner/stop_request',
                                                   RELIABLE)
        self.clients = {name: self.peer.create_client(kind, f'/wafer_planner/{name}')
                        for name, kind in (('get_status', Trigger),
                                           ('rebuild_roadmap', Trigger),
                                           ('set_recording', SetBool))}
        self.executor = MultiThreadedExecutor(num_threads=4, context=self.context)
        for node in (*nodes, self.peer):
            self.executor.add_node(node)
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()
        wait_for(lambda: self.joint_pub.get_subscription_count() > 0
                 and self.station_pub.get_subscription_count() > 0
                 and self.stop_pub.get_subscription_count() > 0
                 and all(c.service_is_ready() for c in self.clients.values()), 20.0)
        wait_for(lambda: self.status()['ready']
                 and self.status()['busy_with'] not in ('load', 'kernels'), 120.0)

    def subscribe_markers(self) -> list:
        """Subscribe to the roadmap markers now (a late subscriber); return the inbox."""
        inbox = []
        self.peer.create_subscription(MarkerArray, '/wafer_planner/roadmap_markers',
                                      inbox.append, LATCHED)
        return inbox

    def call(self, name: str, request=None, resend: bool = False):
        """
        Call a service of the node and return the response; fail after 120 s unanswered.

        ``resend``: for a call that changes nothing (``get_status``). DDS drops a response
        when the node has not yet discovered this client's reader ("failed to send response
        (timeout)" on its side), which can happen to the first calls while the two discover
        each other: such a call unanswered for 5 s is sent again, as ``wafer-plan-client``
        does.
        """
        client = self.clients[name]
        request = request or client.srv_type.Request()
        deadline = time.monotonic() + 120.0
        while True:
            future = client.call_async(request)
            wait = deadline - time.monotonic()
            try:
                wait_for(future.done, min(RESEND, wait) if resend else wait)
                return future.result()
            except AssertionError:
                client.remove_pending_request(future)
                if time.monotonic() >= deadline:
                    raise AssertionError(f'~/{name}: no answer in 120 s') from None

    def status(self) -> dict:
        """Return ``~/get_status`` as a dict."""
        return json.loads(self.call('get_status', resend=True).message)

    def send_stations(self, request: dict) -> None:
        """Publish a station request (JSON)."""
        self.station_pub.publish(String(data=json.dumps(request)))

    def send_stop(self, request: dict) -> None:
        """Publish a stop request (JSON)."""
        self.stop_pub.publish(String(data=json.dumps(request)))

    def send_joints(self, request_id: str, start, goal, joint_names=()) -> None:
        """Publish a joint request."""
        msg = JointTrajectory(joint_names=list(joint_names))
        msg.header.frame_id = request_id
        msg.points = [JointTrajectoryPoint(positions=[float(v) for v in start]),
                      JointTrajectoryPoint(positions=[float(v) for v in goal])]
        self.joint_pub.publish(msg)

    def health(self, since: int, timeout: float = 10.0) -> DiagnosticStatus:
        """Wait for and return the node's first health status after ``since`` received."""
        wait_for(lambda: len(self.diagnostics) > since, timeout)
        return self.diagnostics[since].status[0]

    def result(self, request_id: str, timeout: float = 60.0) -> DiagnosticStatus:
        """Wait for and return the one result of a request."""
        wait_for(lambda: any(r.name == request_id for r in self.results), timeout)
        return next(r for r in self.results if r.name == request_id)

    def close(self) -> None:
        """Stop the executor and the peer."""
        self.executor.shutdown()
        self.thread.join(timeout=10)
        self.peer.destroy_node()


class Harness(Peer):
    """A planner node and a peer node on one private context and executor thread."""

    def __init__(self, parameters: dict):
        """Start the node with ``parameters`` (name -> value) and wait until it is ready."""
        # The station table and the budgeted optimisation take seconds to minutes of CPU
        # and their answers depend on time: off unless a test turns them on.
        parameters = {'recording.directory': tempfile.mkdtemp(prefix='wafer_recordings_'),
                      'planning.station_table': False, 'planning.optimise_budget': 0.0,
                      **parameters}
        self.recordings = parameters['recording.directory']
        # As the node's own process runs it (``planner_node.main``): the executor's threads
        # get the GIL within 1 ms of planning (5 ms by default), which the deadlines rely on.
        sys.setswitchinterval(0.001)
        context = rclpy.Context()
        rclpy.init(context=context)
        overrides = [Parameter(k, value=v) for k, v in parameters.items()]
        self.node = WaferPlannerNode(context=context, parameter_overrides=overrides)
        super().__init__(context, [self.node])

    def close(self) -> None:
        """Stop everything."""
        super().close()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


def values(status: DiagnosticStatus) -> dict:
    """Return a result's key/values."""
    return {kv.key: kv.value for kv in status.values}


def wait_for(predicate, timeout: float) -> None:
    """Wait on the steady clock until ``predicate()`` holds; fail after ``timeout``."""
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f'timed out after {timeout} s')
        time.sleep(0.01)
