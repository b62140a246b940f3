"""
The stop requests' own way in, waited on by the thread that answers them.

A stop request must not wait behind the node's executor (status queries, answers being
published, the live view's relays) nor be handed from one thread to another. So
``StopRequests`` subscribes to the planner node's ``~/stop_request`` (the name as that
node resolves it: remapped as its own topics are) from a second node in the same process,
``<name>_stops`` (without the command line's global arguments, so that a ``__node`` remap
renames the planner node alone), which no executor spins: the stop thread waits on the
subscription itself (``serve``: an rcl wait set, as rclpy's executors wait, holding only
it and a guard condition that wakes it to close), and as soon as a request is there marks
its work urgent (``giving_way``: the other threads pause at their next kernel call), takes
it, and answers, records and publishes it in the callback, in that one thread.
"""

from typing import Callable

import rclpy
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from std_msgs.msg import String

from wafer_planner_ros.giving_way import urgent
from wafer_planner_ros.node.qos import RELIABLE

SUFFIX = '_stops'
"""The stop requests' node is the planner node's name with this after it."""


class StopRequests:
    """The subscription to ``~/stop_request``, on a node of its own, and its waiting."""

    def __init__(self, node, callback: Callable):
        """
        Subscribe ``callback(data, info)`` (raw bytes, rmw's message info) beside ``node``.

        Nothing is taken until ``serve`` is called.
        """
        self.topic_name = node.resolve_topic_name('~/stop_request')
        self._context = node.context
        self._node = rclpy.create_node(node.get_name() + SUFFIX,
                                       namespace=node.get_namespace(), context=node.context,
                                       use_global_arguments=False,
                                       start_parameter_services=False)
        # Raw: the request's bytes are recorded exactly as they arrived. No executor calls
        # it: ``serve`` takes each message itself.
        self._subscription = self._node.create_subscription(
            String, self.topic_name, callback, RELIABLE, raw=True)
        self._callback = callback
        with self._context.handle:
            self._wake = _rclpy.GuardCondition(self._context.handle)
        self._closed = False

    def serve(self, timeout: float) -> bool:
        """
        Wait up to ``timeout`` s for a stop request and answer it, in this thread, urgently.

        Return False once closed or ROS is shut down (nothing more will come), else True.
        """
        if self._closed or not self._context.ok():
            return False
        handle = self._subscription.handle
        with handle, self._wake, self._context.handle:
            waiting = _rclpy.WaitSet(1, 1, 0, 0, 0, 0, self._context.handle)
            waiting.clear_entities()
            waiting.add_subscription(handle)
            waiting.add_guard_condition(self._wake)
            waiting.wait(int(timeout * 1e9))
            if self._closed or not waiting.get_ready_entities('subscription'):
                return not self._closed and self._context.ok()
            with urgent():
                taken = handle.take_message(String, True)
                if taken is not None:
                    self._callback(*taken)
        return True

    def close(self) -> None:
        """Stop taking requests (waking the thread waiting for one) and destroy the node."""
        self._closed = True
        try:
            self._wake.trigger_guard_condition()
        except Exception:  # noqa: B902 - the context is shut down already: nothing waits
            pass
        self._node.destroy_node()
        self._wake.destroy_when_not_in_use()
