r"""
Launch a two-wheel base on ros2_control with drive_bridge driving its two FC 51s.

ros2 launch drive_bridge two_wheel_base.launch.py \\
    bridge_params:=/path/my_base.yaml namespace:=base

Starts robot_state_publisher (the URDF of ``two_wheel_base.urdf.xacro``, expanded here with
the bridge's topics), the controller manager (``ros2_control_node``, 100 Hz, with
``joint_state_topic_hardware_interface/JointStateTopicSystem`` as the hardware), the
spawners of ``joint_state_broadcaster`` and ``diff_drive_controller``, and drive_bridge
(a lifecycle node that activates itself). Drive the base with TwistStamped messages on
``/diff_drive_controller/cmd_vel``. Needs, besides drive_bridge: ros-jazzy-xacro,
ros-jazzy-robot-state-publisher, ros-jazzy-controller-manager,
ros-jazzy-diff-drive-controller, ros-jazzy-joint-state-broadcaster and
ros-jazzy-joint-state-topic-hardware-interface.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import LifecycleNode, Node
from launch_ros.parameter_descriptions import ParameterValue

CONTROLLERS = ('joint_state_broadcaster', 'diff_drive_controller')


def _example(name: str) -> str:
    return os.path.join(get_package_share_directory('drive_bridge'), 'config', 'ros2_control',
                        name)


def _nodes(context):
    """Return the nodes, with the URDF expanded for the bridge's namespace."""
    import xacro
    namespace = LaunchConfiguration('namespace').perform(context).strip('/')
    bridge = '/' + '/'.join(part for part in (namespace, 'drive_bridge') if part)
    description = xacro.process_file(_example('two_wheel_base.urdf.xacro'),
                                     mappings={'bridge': bridge}).toxml()
    controllers = _example('controllers.yaml')
    return [
        Node(package='robot_state_publisher', executable='robot_state_publisher',
             parameters=[{'robot_description': ParameterValue(description, value_type=str)}],
             output='screen'),
        Node(package='controller_manager', executable='ros2_control_node',
             parameters=[controllers], output='screen'),
        *[Node(package='controller_manager', executable='spawner',
               arguments=[controller, '--controller-manager', '/controller_manager',
                          '--param-file', controllers], output='screen')
          for controller in CONTROLLERS],
        LifecycleNode(package='drive_bridge', executable='drive_bridge_node',
                      name='drive_bridge', namespace=namespace,
                      parameters=[LaunchConfiguration('bridge_params').perform(context)],
                      output='screen', emulate_tty=True),
    ]


def generate_launch_description() -> LaunchDescription:
    """Return the base: arguments, then the nodes."""
    return LaunchDescription([
        DeclareLaunchArgument(
            'bridge_params', default_value=_example('drive_bridge.yaml'),
            description='drive_bridge parameters: the bus and the two wheel drives'),
        DeclareLaunchArgument('namespace', default_value='',
                              description="drive_bridge's namespace, e.g. base"),
        OpaqueFunction(function=_nodes),
    ])
