"""The ROS 2 edge: the planning node, its messages, markers and client."""
