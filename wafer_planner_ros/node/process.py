"""
One node in its own process: spun until Ctrl-C or SIGTERM, ended cleanly whatever happens.

``spin(make, name)`` is what the planner node's and the simulated arm's ``main`` share:
ROS started, the node made and spun on a single-threaded executor, then everything shut
down. A bad parameter ends it with exit code 2 and a message naming it; an interrupt,
even one that arrives before the node spins (the context is then shut down under it),
with 0.
"""

from typing import Callable

import rclpy
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor

BAD_PARAMETER = 2
"""The exit code of a node refusing a parameter."""


def spin(make: Callable, name: str, args=None) -> int:
    """Make a node with ``make()`` and spin it until interrupted; return the exit code."""
    rclpy.init(args=args)
    node, executor, code = None, None, 0
    try:
        executor = SingleThreadedExecutor()
        node = make()
        executor.add_node(node)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except (ValueError, ParameterException) as exc:
        print(f'{name}: bad parameter: {exc}', flush=True)
        code = BAD_PARAMETER
    except Exception:  # noqa: B902 - a signal before spinning shuts the context down
        if rclpy.ok():
            raise
    finally:
        if executor is not None:
            executor.shutdown()
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return code
