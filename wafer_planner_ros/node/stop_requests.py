"""
The stop requests' own way in: a node of their own, spun by the thread that answers them.

A stop request must not wait behind the node's executor (status queries, answers being
published, the live view's relays) nor be handed from one thread to another. So
``StopRequests`` subscribes to the planner node's ``~/stop_request`` (the name as that
node resolves it: remapped as its own topics are) from a second node in the same process,
``<name>_stops`` (without the command line's global arguments, so that a ``__node`` remap
renames the planner node alone), whose executor only the stop thread spins (``serve``):
a request is taken, answered and published by that one thread, in its callback.
"""

from typing import Callable

import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from std_msgs.msg import String

from wafer_planner_ros.node.qos import RELIABLE

SUFFIX = '_stops'
"""The stop requests' node is the planner node's name with this after it."""


class StopRequests:
    """The subscription to ``~/stop_request`` on a node and executor of its own."""

    def __init__(self, node, callback: Callable):
        """
        Subscribe ``callback(data, info)`` (raw bytes, rmw's message info) beside ``node``.

        Nothing is taken until ``serve`` is called.
        """
        self.topic_name = node.resolve_topic_name('~/stop_request')
        self._node = rclpy.create_node(node.get_name() + SUFFIX,
                                       namespace=node.get_namespace(), context=node.context,
                                       use_global_arguments=False,
                                       start_parameter_services=False)
        # Raw: the request's bytes are recorded exactly as they arrived.
        self._node.create_subscription(String, self.topic_name, callback, RELIABLE, raw=True)
        self._executor = SingleThreadedExecutor(context=node.context)
        self._executor.add_node(self._node)

    def serve(self, timeout: float) -> bool:
        """
        Wait up to ``timeout`` s for a stop request and take it, in this thread.

        Return False once ROS is shut down (nothing more will come), else True.
        """
        try:
            self._executor.spin_once(timeout_sec=timeout)
        except (ExternalShutdownException, rclpy.executors.ShutdownException):
            return False
        return True

    def close(self) -> None:
        """Stop taking requests (waiting for one being answered) and destroy the node."""
        self._executor.shutdown(timeout_sec=1.0)
        self._node.destroy_node()
