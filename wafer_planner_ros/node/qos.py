"""
The QoS the planner node, the simulated arm and their peers publish and subscribe with.

``RELIABLE``: requests, answers and trajectories, reliable and keep-all, so that a burst is
delivered whole (a keep-last reader cache drops the oldest samples of a burst longer than
its depth). ``LATCHED``: markers, the last one kept for whoever subscribes later.
"""

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

RELIABLE = QoSProfile(depth=1000, history=HistoryPolicy.KEEP_ALL,
                      reliability=ReliabilityPolicy.RELIABLE)
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
