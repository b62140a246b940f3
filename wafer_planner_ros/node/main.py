"""
``wafer_planner_node``: the node's process, the compiled kernels loading from its first moment.

The kernels load in a thread of their own (``startup.load_kernels``), started here before
the node's own imports: the build made ahead of time loads in milliseconds, but numba's
cache (when there is no build for this machine) takes longer than all the rest of the
start-up (imports, ROS, the roadmap from its cache). The node is ready when both are done.
"""

from wafer_planner_ros.node import startup


def entry_point() -> None:
    """Console script ``wafer_planner_node`` (and ``python -m wafer_planner_ros.node.main``)."""
    startup.load_kernels()
    from wafer_planner_ros.node import planner_node  # ROS and the node, meanwhile
    planner_node.entry_point()


if __name__ == '__main__':
    entry_point()
