"""The planner as a service, ROS-free: requests, the node's parameters, CDR encoding."""
