"""Launch wafer_planner_node with a cell file and a parameters file."""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def generate_launch_description():
    """Return the launch description: arguments cell_file and params_file."""
    share = get_package_share_directory('wafer_planner_ros')
    return LaunchDescription([
        DeclareLaunchArgument('cell_file', default_value='',
                              description='cell YAML file; empty: the packaged default cell'),
        DeclareLaunchArgument('params_file',
                              default_value=os.path.join(share, 'config', 'wafer_planner.yaml'),
                              description='parameters file'),
        Node(package='wafer_planner_ros', executable='wafer_planner_node',
             name='wafer_planner', output='screen',
             parameters=[LaunchConfiguration('params_file'),
                         {'cell_file': LaunchConfiguration('cell_file')}]),
    ])
