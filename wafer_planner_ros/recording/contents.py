"""
What a recording holds beside the messages, named once for the node and the tools.

Each roadmap load adds the cell file as the attachment ``cell.yaml`` and a metadata record
``wafer_planner`` (cell, cell file and digest, roadmap hash, nodes, edges, seed, load time
``loaded_ns``). The node's parameters are attached as ``parameters.yaml`` (a ROS 2
``--params-file``) when recording starts and whenever they change. A request, its trajectory
and its result carry the query number as their MCAP ``sequence``; the markers carry 0.
"""

from typing import Dict, Mapping

import yaml

CELL_ATTACHMENT = 'cell.yaml'
PARAMETERS_ATTACHMENT = 'parameters.yaml'
LOAD_METADATA = 'wafer_planner'


def parameters_file(node_name: str, values: Mapping[str, object]) -> bytes:
    """Return parameter values as a ROS 2 ``--params-file``."""
    return yaml.safe_dump({node_name: {'ros__parameters': dict(values)}},
                          sort_keys=False).encode()


def read_parameters(data: bytes) -> Dict[str, object]:
    """Return the parameter values of a ``--params-file`` written by ``parameters_file``."""
    document = yaml.safe_load(data) or {}
    for node in document.values():
        return dict(node.get('ros__parameters', {}))
    return {}
