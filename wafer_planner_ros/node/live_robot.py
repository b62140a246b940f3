"""
The robot in the live view: its joint states, its arm's markers and its wafer acceleration.

The live view serves what the planner node publishes; a robot is another node. With the
view on (``live.port``) and ``live.robot`` naming that node (``/wafer_sim`` by default: the
simulated arm ``make run`` starts), the planner node subscribes to ``/joint_states``,
``<robot>/arm_markers`` and ``<robot>/wafer_acceleration`` and hands every message on to
the view as it arrived (its CDR bytes, never decoded), so that Foxglove shows the arm moving
in the cell beside the plans and the wafer's acceleration against its limit (the last of
its three numbers is the ratio). A real robot's driver publishes ``/joint_states`` too: with
``live.robot`` empty only that is relayed. With the view off nothing is subscribed.
"""

from typing import List, Tuple

from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
from visualization_msgs.msg import MarkerArray

from wafer_planner_ros.node.qos import LATCHED

JOINT_STATES = '/joint_states'
ROBOT_TOPICS = (('arm_markers', MarkerArray, LATCHED),
                ('wafer_acceleration', Float64MultiArray, 10))
"""The robot node's topics relayed (name under it, type, QoS)."""


def robot_topics(robot: str) -> List[Tuple[str, type, object]]:
    """Return (topic, type, QoS) of what is relayed for the robot node ``robot`` ('': none)."""
    robot = robot.rstrip('/')
    return [(JOINT_STATES, JointState, 10)] + [
        (f'{robot}/{name}', kind, qos) for name, kind, qos in ROBOT_TOPICS if robot]


class RobotRelay:
    """The subscriptions that hand a robot's topics on to a live view (see the module)."""

    def __init__(self, node, view):
        """Relay nothing yet; ``view``: the node's ``live.LiveView``."""
        self.node, self.view = node, view
        self._subscriptions = []
        self._following = None

    def follow(self, robot: str, on: bool) -> None:
        """Relay the topics of ``robot`` while ``on`` (the view serves); call before it starts."""
        wanted = robot if on else None
        if wanted == self._following:
            return
        for subscription in self._subscriptions:
            self.node.destroy_subscription(subscription)
        self._subscriptions, self._following = [], wanted
        if wanted is not None:
            self._subscriptions = [
                self.node.create_subscription(kind, topic, self._handler(topic), qos, raw=True)
                for topic, kind, qos in robot_topics(wanted)]
        self.view.relay(self._subscriptions)

    def _handler(self, topic: str):
        subscription = _Topic(topic)
        return lambda data: self.view.publish(subscription, data)


class _Topic:
    """What ``LiveView.publish`` reads of a publisher: its topic's name."""

    def __init__(self, topic: str):
        self.topic_name = topic
