"""
``wafer-plan-client FROM TO``: ask a running wafer_planner node for one plan (SPEC section 4).

FROM/TO are station names or ``q1,q2,q3``. The client waits until the node reports ready
(``~/get_status``), sends the request to ``~/plan_station_request`` and prints the
``~/result`` with the request's id (and the trajectory's size). Exit 0 when
the plan is ok, 1 when the node answered with an error or did not answer in time, 2 on a
bad command line.
"""

import argparse
import json
import os
import sys
import time

from diagnostic_msgs.msg import DiagnosticStatus
import rclpy
from rclpy.node import Node
from std_msgs.msg import String
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory

from wafer_planner_ros.node.planner_node import RELIABLE
from wafer_planner_ros.service.requests import end_of_text, with_negative_ends


def main(argv=None) -> int:
    """Send the request, wait for its result, print it."""
    parser = argparse.ArgumentParser(prog='wafer-plan-client', description=__doc__.split('\n')[1])
    parser.add_argument('start', metavar='FROM', help='station name or q1,q2,q3')
    parser.add_argument('goal', metavar='TO', help='station name or q1,q2,q3')
    parser.add_argument('--id', help='request id (default: client-<pid>-<time>)')
    parser.add_argument('--timeout', type=float, default=30.0,
                        help='seconds to wait for the node (a first run compiles for ~10 s) '
                             'and its answer (default: 30)')
    parser.add_argument('--node', default='/wafer_planner',
                        help='the planner node (default: /wafer_planner)')
    args = parser.parse_args(with_negative_ends(sys.argv[1:] if argv is None else argv))
    try:
        ends = [end_of_text(args.start), end_of_text(args.goal)]
    except ValueError as exc:
        parser.error(str(exc))
    request_id = args.id or f'client-{os.getpid()}-{int(time.time() * 1000)}'
    rclpy.init()
    try:
        client = _Client(args.node)
        answer = client.ask({'id': request_id, 'from': ends[0], 'to': ends[1]}, args.timeout)
        client.destroy_node()
    except KeyboardInterrupt:
        answer = None
    finally:
        rclpy.try_shutdown()
    if answer is None:
        print(f'{request_id}: no answer from {args.node} within {args.timeout:g} s',
              file=sys.stderr)
        return 1
    status, trajectory = answer
    values = {kv.key: kv.value for kv in status.values}
    print(f'{request_id}: {status.message}')
    for key, value in values.items():
        print(f'  {key}: {value}')
    if trajectory is not None:
        print(f'  trajectory: {len(trajectory.points)} points')
    return 0 if status.level in (DiagnosticStatus.OK, DiagnosticStatus.WARN) else 1


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

    def wait_ready(self, deadline: float, publishers) -> bool:
        """Spin until the planner is ready and hears ``publishers``; False after ``deadline``."""
        while not self._ready() or any(p.get_subscription_count() == 0 for p in publishers) \
                or self.count_publishers(f'{self.planner}/result') == 0:
            if time.monotonic() > deadline:
                return False
            rclpy.spin_once(self, timeout_sec=0.1)
        return True

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

    def _ready(self) -> bool:
        """Return whether the planner answers ``~/get_status`` with ready."""
        return bool(self.planner_status().get('ready'))


class _Client(PlannerPeer):
    def __init__(self, planner: str):
        super().__init__(f'wafer_plan_client_{os.getpid()}', planner)
        self.trajectories = {}
        self.create_subscription(JointTrajectory, f'{planner}/trajectory',
                                 lambda m: self.trajectories.setdefault(m.header.frame_id, m),
                                 RELIABLE)
        self.requests = self.create_publisher(String, f'{planner}/plan_station_request',
                                              RELIABLE)

    def ask(self, request: dict, timeout: float):
        """Return (result, trajectory or None) for the request, or None after ``timeout``."""
        deadline = time.monotonic() + timeout
        if not self.wait_ready(deadline, [self.requests]):
            return None
        self.requests.publish(String(data=json.dumps(request)))
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


def entry_point() -> None:
    """Console script ``wafer-plan-client``."""
    raise SystemExit(main())


if __name__ == '__main__':
    entry_point()
