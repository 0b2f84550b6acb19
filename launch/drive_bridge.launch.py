r"""
Launch drive_bridge with a parameters file (apt/colcon ROS installs).

ros2 launch drive_bridge drive_bridge.launch.py params_file:=/path/line1.yaml \\
    namespace:=line1 aggregator:=true

The node is a managed (lifecycle) node; with ``autostart`` (default true in the parameters)
it configures and activates itself. ``aggregator:=true`` also starts diagnostic_aggregator
with this package's analyzer configuration (devices grouped under "Drives and starters").
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import LifecycleNode, Node


def generate_launch_description() -> LaunchDescription:
    """Return the node, and optionally the diagnostic aggregator."""
    share = get_package_share_directory('drive_bridge')
    return LaunchDescription([
        DeclareLaunchArgument(
            'params_file', default_value=os.path.join(share, 'config', 'mcd.yaml'),
            description='the bus and device parameters (see config/*.yaml)'),
        DeclareLaunchArgument('namespace', default_value='',
                              description='one namespace per bus, e.g. line1'),
        DeclareLaunchArgument('aggregator', default_value='false',
                              description='also start diagnostic_aggregator'),
        LifecycleNode(
            package='drive_bridge', executable='drive_bridge_node', name='drive_bridge',
            namespace=LaunchConfiguration('namespace'),
            parameters=[LaunchConfiguration('params_file')], output='screen',
            emulate_tty=True),
        Node(
            package='diagnostic_aggregator', executable='aggregator_node',
            parameters=[os.path.join(share, 'config', 'diagnostic_aggregator.yaml')],
            condition=IfCondition(LaunchConfiguration('aggregator')), output='screen'),
    ])
