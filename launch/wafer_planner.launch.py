"""
Launch wafer_planner_node with a parameters file, and place its frame in a TF tree.

Arguments (``ros2 launch wafer_planner_ros wafer_planner.launch.py --show-args``):

- ``params_file``: the node's parameters (default: the packaged ``config/wafer_planner.yaml``);
- ``cell_file``, ``frame_id``: set ``cell_file`` / ``markers.frame_id`` only when given, so
  that a params file's values stand otherwise;
- ``parent_frame`` with ``x``, ``y``, ``z``, ``yaw``: when a parent frame is given, a
  ``tf2_ros`` static transform publisher places the markers' frame in it (the cell frame at
  that pose), so that RViz and Foxglove can show the markers in the rest of the tree.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, LogInfo, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
import yaml

NODE = 'wafer_planner'
DEFAULT_FRAME = 'efem'


def generate_launch_description():
    """Return the launch description (see the module's description)."""
    share = get_package_share_directory('wafer_planner_ros')
    arguments = [
        ('params_file', os.path.join(share, 'config', 'wafer_planner.yaml'),
         'parameters file'),
        ('cell_file', '', 'cell YAML file; empty: as the params file says (or the packaged '
                          'cell)'),
        ('frame_id', '', f'markers.frame_id; empty: as the params file says (or '
                         f'{DEFAULT_FRAME})'),
        ('parent_frame', '', 'a frame to place the cell frame in (a static transform); '
                             'empty: none'),
        ('x', '0.0', 'x of the cell frame in the parent frame (m)'),
        ('y', '0.0', 'y of the cell frame in the parent frame (m)'),
        ('z', '0.0', 'z of the cell frame in the parent frame (m)'),
        ('yaw', '0.0', 'rotation of the cell frame about z in the parent frame (rad)'),
    ]
    return LaunchDescription(
        [DeclareLaunchArgument(name, default_value=default, description=description)
         for name, default, description in arguments] + [OpaqueFunction(function=_actions)])


def _actions(context):
    """Return the node and, with a parent frame, the static transform publisher."""
    value = {name: LaunchConfiguration(name).perform(context)
             for name in ('params_file', 'cell_file', 'frame_id', 'parent_frame',
                          'x', 'y', 'z', 'yaw')}
    given = {}  # after the params file: these override it only when given
    if value['cell_file']:
        given['cell_file'] = value['cell_file']
    if value['frame_id']:
        given['markers.frame_id'] = value['frame_id']
    parameters = [value['params_file']] + ([given] if given else [])
    actions = [Node(package='wafer_planner_ros', executable='wafer_planner_node', name=NODE,
                    output='screen', parameters=parameters)]
    if not value['parent_frame']:
        return actions
    try:
        get_package_share_directory('tf2_ros')
    except Exception:  # noqa: B902 - PackageNotFoundError: no tf2_ros in this install
        return actions + [LogInfo(msg='parent_frame given, but tf2_ros is not installed: '
                                      'no static transform is published')]
    frame = value['frame_id'] or _params_frame(value['params_file'])
    actions.append(Node(
        package='tf2_ros', executable='static_transform_publisher',
        name=f'{NODE}_frame', output='screen',
        arguments=['--x', value['x'], '--y', value['y'], '--z', value['z'],
                   '--yaw', value['yaw'], '--frame-id', value['parent_frame'],
                   '--child-frame-id', frame]))
    return actions


def _params_frame(path: str) -> str:
    """Return ``markers.frame_id`` as the params file sets it for the node (or the default)."""
    try:
        with open(path) as stream:
            document = yaml.safe_load(stream) or {}
    except (OSError, yaml.YAMLError):
        return DEFAULT_FRAME  # the node reports an unreadable params file itself
    for key in (NODE, f'/{NODE}', '/**'):  # the node's own section first
        section = document.get(key) if isinstance(document, dict) else None
        parameters = section.get('ros__parameters') if isinstance(section, dict) else None
        if isinstance(parameters, dict):
            markers = parameters.get('markers')
            if isinstance(markers, dict) and isinstance(markers.get('frame_id'), str):
                return markers['frame_id']
            if isinstance(parameters.get('markers.frame_id'), str):
                return parameters['markers.frame_id']
    return DEFAULT_FRAME
