r"""
Launch several buses, one drive_bridge node each in its own namespace, and one aggregator.

ros2 launch drive_bridge buses.launch.py \\
    buses:='line1=/path/line1.yaml;line2=/path/line2.yaml'

Each entry ``NAMESPACE=PARAMS_FILE`` starts one lifecycle node ``/NAMESPACE/drive_bridge``.
Their ``/diagnostics`` status names carry the namespace (``/line1/drive_bridge: feeder``), so
devices of the same name on two buses stay apart; one diagnostic_aggregator (``aggregator``,
default true) groups them all under "Drives and starters". Start the aggregator once: a
second aggregator would publish a second ``/diagnostics_agg``.
"""

import os
from typing import List

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import LifecycleNode, Node


def parse_buses(text: str) -> List[tuple]:
    """Return [(namespace, params file)] of ``line1=/a.yaml;line2=/b.yaml``; raise ValueError."""
    buses = []
    for entry in filter(None, (part.strip() for part in text.split(';'))):
        namespace, sign, path = entry.partition('=')
        if not sign or not namespace.strip() or not path.strip():
            raise ValueError(f'buses: {entry!r} is not NAMESPACE=PARAMS_FILE')
        buses.append((namespace.strip().strip('/'), path.strip()))
    if not buses:
        raise ValueError('buses: give at least one NAMESPACE=PARAMS_FILE')
    if len({namespace for namespace, _ in buses}) != len(buses):
        raise ValueError('buses: each bus needs a namespace of its own')
    return buses


def _bus_nodes(context) -> list:
    buses = parse_buses(LaunchConfiguration('buses').perform(context))
    return [LifecycleNode(package='drive_bridge', executable='drive_bridge_node',
                          name='drive_bridge', namespace=namespace, parameters=[path],
                          output='screen', emulate_tty=True)
            for namespace, path in buses]


def generate_launch_description() -> LaunchDescription:
    """Return one node per bus, and the diagnostic aggregator."""
    share = get_package_share_directory('drive_bridge')
    return LaunchDescription([
        DeclareLaunchArgument('buses', description='NAMESPACE=PARAMS_FILE;... one per bus'),
        DeclareLaunchArgument('aggregator', default_value='true',
                              description='also start diagnostic_aggregator (once)'),
        OpaqueFunction(function=_bus_nodes),
        Node(
            package='diagnostic_aggregator', executable='aggregator_node',
            parameters=[os.path.join(share, 'config', 'diagnostic_aggregator.yaml')],
            condition=IfCondition(LaunchConfiguration('aggregator')), output='screen'),
    ])
