"""
The ros2_control example under config/ros2_control: it parses, and its parts agree.

ros2_control, the controllers and JointStateTopicSystem are C++ and not on PyPI, so the
example cannot run here: the URDF is expanded with xacro (PyPI), the YAML files are read,
the launch file is run with stand-ins for launch and launch_ros, and the names and numbers
that must match between the URDF, the controllers, drive_bridge's parameters and the
hardware interface's parameters are checked. The topic contract itself is tested in
test/ros/test_joints_node.py.
"""

import importlib.util
import os
import re
import sys
import types
from xml.etree import ElementTree

from drive_bridge.config import model as config
import pytest
import yaml

# Neither is in the pymodbus 3.6.9 venv (transport tiers only): skipped there.
joints = pytest.importorskip('drive_bridge.ros.node.joints', reason='ROS 2 (rclpy) from PyPI')
xacro = pytest.importorskip('xacro', reason='pip install xacro')

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), '..', '..'))
EXAMPLE = os.path.join(ROOT, 'config', 'ros2_control')
XACRO = os.path.join(EXAMPLE, 'two_wheel_base.urdf.xacro')
PLUGIN = 'joint_state_topic_hardware_interface/JointStateTopicSystem'
# The <hardware> parameters JointStateTopicSystem reads (topic_based_hardware_interfaces
# 1.1.0, joint_state_topic_hardware_interface.cpp, on_init).
HARDWARE_PARAMETERS = {'joint_commands_topic', 'joint_states_topic',
                       'trigger_joint_command_threshold', 'sum_wrapped_joint_states'}


def urdf(bridge='/drive_bridge') -> ElementTree.Element:
    return ElementTree.fromstring(xacro.process_file(XACRO, mappings={'bridge': bridge})
                                  .toxml())


def load_yaml(name):
    with open(os.path.join(EXAMPLE, name)) as stream:
        return yaml.safe_load(stream)


def bridge_config():
    parameters = dict(load_yaml('drive_bridge.yaml')['/**/drive_bridge']['ros__parameters'])
    names = parameters['devices']
    return config.build_config(parameters, {name: parameters.pop(name) for name in names})


def test_the_xacro_file_is_xml_and_expands():
    ElementTree.parse(XACRO)
    robot = urdf()
    assert robot.tag == 'robot' and robot.get('name') == 'two_wheel_base'
    assert {joint.get('name') for joint in robot.findall('joint')} == \
        {'left_wheel_joint', 'right_wheel_joint'}


@pytest.mark.parametrize('bridge', ['/drive_bridge', '/base/drive_bridge'])
def test_the_hardware_is_joint_state_topic_system_on_the_bridge_topics(bridge):
    hardware = urdf(bridge).find('ros2_control/hardware')
    assert hardware.findtext('plugin') == PLUGIN
    parameters = {param.get('name'): param.text for param in hardware.findall('param')}
    assert set(parameters) == HARDWARE_PARAMETERS  # spelled as the interface reads them
    assert parameters['joint_states_topic'] == bridge + joints.STATES_TOPIC[1:]
    assert parameters['joint_commands_topic'] == bridge + joints.COMMANDS_TOPIC[1:]
    # Commands go out every cycle: the interface skips one when |state - command| summed
    # over the joints is <= the threshold, and that sum is never below 0.
    assert float(parameters['trigger_joint_command_threshold']) < 0.0
    assert parameters['sum_wrapped_joint_states'] == 'false'  # our positions never wrap


def test_the_joints_are_velocity_commanded_with_position_and_velocity_states():
    robot = urdf()
    urdf_joints = {joint.get('name'): joint for joint in robot.findall('joint')}
    control = robot.find('ros2_control')
    assert control.get('type') == 'system'
    for joint in control.findall('joint'):
        assert urdf_joints[joint.get('name')].get('type') == 'continuous'
        commands = joint.findall('command_interface')
        assert [c.get('name') for c in commands] == ['velocity']
        initial = {p.get('name'): p.text for p in commands[0].findall('param')}
        assert float(initial['initial_value']) == 0.0
        assert [s.get('name') for s in joint.findall('state_interface')] == \
            ['position', 'velocity']


def test_the_bridge_parameters_name_the_same_joints():
    built = bridge_config()
    specs = joints.joint_specs(built.devices)
    control_joints = [joint.get('name') for joint in urdf().findall('ros2_control/joint')]
    assert sorted(spec.name for spec in specs) == sorted(control_joints)
    assert [spec.velocity_scale for spec in specs] == [7.435, -7.435]
    for device in built.devices:
        assert device.option('reference_timeout') > 0  # the deadman is on
        assert device.option('comms_timeout') > 0  # and the drive's own timeout


def test_the_controllers_match_the_urdf_and_stay_within_100_percent():
    controllers = load_yaml('controllers.yaml')
    manager = controllers['controller_manager']['ros__parameters']
    assert manager['update_rate'] == 100
    assert manager['joint_state_broadcaster']['type'] == \
        'joint_state_broadcaster/JointStateBroadcaster'
    assert manager['diff_drive_controller']['type'] == 'diff_drive_controller/DiffDriveController'
    drive = controllers['diff_drive_controller']['ros__parameters']
    assert drive['left_wheel_names'] == ['left_wheel_joint']
    assert drive['right_wheel_names'] == ['right_wheel_joint']
    robot = urdf()
    radius = float(robot.find("link[@name='left_wheel_link']/visual/geometry/cylinder")
                   .get('radius'))
    left_y = float(robot.find("joint[@name='left_wheel_joint']/origin").get('xyz').split()[1])
    right_y = float(robot.find("joint[@name='right_wheel_joint']/origin").get('xyz').split()[1])
    assert drive['wheel_radius'] == radius
    assert drive['wheel_separation'] == pytest.approx(left_y - right_y)
    fastest_wheel = (drive['linear.x.max_velocity'] + drive['angular.z.max_velocity'] *
                     drive['wheel_separation'] / 2) / drive['wheel_radius']
    scale = min(abs(spec.velocity_scale) for spec in joints.joint_specs(bridge_config().devices))
    assert fastest_wheel <= scale  # never above the drives' 100 % reference
    assert controllers['joint_state_broadcaster']['ros__parameters']['joints'] == \
        drive['left_wheel_names'] + drive['right_wheel_names']


class Recorded:
    """A stand-in action that keeps its arguments."""

    def __init__(self, *args, **kwargs):
        self.args, self.kwargs = args, kwargs


class Configuration:
    """A stand-in LaunchConfiguration: performs to the context's value."""

    def __init__(self, name):
        self.name = name

    def perform(self, context):
        return context[self.name]


def _module(name, **attributes):
    module = types.ModuleType(name)
    module.__dict__.update(attributes)
    return module


@pytest.fixture
def launch_file(monkeypatch):
    stand_ins = {
        'launch': _module('launch', LaunchDescription=Recorded),
        'launch.actions': _module('launch.actions', DeclareLaunchArgument=Recorded,
                                  OpaqueFunction=Recorded),
        'launch.substitutions': _module('launch.substitutions',
                                        LaunchConfiguration=Configuration),
        'launch_ros': _module('launch_ros'),
        'launch_ros.actions': _module('launch_ros.actions', LifecycleNode=Recorded,
                                      Node=Recorded),
        'launch_ros.parameter_descriptions': _module('launch_ros.parameter_descriptions',
                                                     ParameterValue=Recorded),
        'ament_index_python.packages': _module(
            'ament_index_python.packages', get_package_share_directory=lambda package: ROOT),
    }
    for name, module in stand_ins.items():
        monkeypatch.setitem(sys.modules, name, module)
    spec = importlib.util.spec_from_file_location(
        'two_wheel_base_launch', os.path.join(EXAMPLE, 'two_wheel_base.launch.py'))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize('namespace, bridge', [('', '/drive_bridge'),
                                               ('/base', '/base/drive_bridge')])
def test_the_launch_file_starts_the_controllers_and_the_bridge(launch_file, namespace, bridge):
    actions = launch_file.generate_launch_description().args[0]
    arguments = {action.args[0]: action.kwargs['default_value'] for action in actions
                 if 'default_value' in action.kwargs}
    assert set(arguments) == {'bridge_params', 'namespace'}
    assert os.path.exists(arguments['bridge_params'])
    opaque = next(action for action in actions if 'function' in action.kwargs)
    nodes = opaque.kwargs['function']({'namespace': namespace,
                                       'bridge_params': arguments['bridge_params']})
    by_executable = {}
    for node in nodes:
        by_executable.setdefault(node.kwargs['executable'], []).append(node)
    description = by_executable['robot_state_publisher'][0].kwargs['parameters'][0][
        'robot_description']
    assert description.kwargs['value_type'] is str
    hardware = ElementTree.fromstring(description.args[0]).find('ros2_control/hardware')
    assert {p.get('name'): p.text for p in hardware.findall('param')}['joint_states_topic'] \
        == bridge + '/joint_states'
    manager = by_executable['ros2_control_node'][0]
    assert manager.kwargs['package'] == 'controller_manager'
    controllers = manager.kwargs['parameters'][0]
    assert controllers == os.path.join(EXAMPLE, 'controllers.yaml')
    spawned = [node.kwargs['arguments'] for node in by_executable['spawner']]
    assert sorted(arguments[0] for arguments in spawned) == \
        ['diff_drive_controller', 'joint_state_broadcaster']
    assert all(arguments[arguments.index('--param-file') + 1] == controllers
               for arguments in spawned)
    bridge_node = by_executable['drive_bridge_node'][0]
    assert bridge_node.kwargs['package'] == 'drive_bridge'
    assert bridge_node.kwargs['name'] == 'drive_bridge'
    assert bridge_node.kwargs['namespace'] == namespace.strip('/')
    assert bridge_node.kwargs['parameters'] == [arguments['bridge_params']]


def recipe_block(command: str) -> str:
    """Return the first line of docs/ros2_control.md's simulator recipe that starts so."""
    with open(os.path.join(ROOT, 'docs', 'ros2_control.md'), encoding='utf-8') as stream:
        section = stream.read().split('## Against the simulator')[1].split('\n## ')[0]
    return next(line for line in section.splitlines() if line.startswith(command))


def test_the_apt_line_installs_what_the_launch_file_needs():
    with open(os.path.join(EXAMPLE, 'two_wheel_base.launch.py'), encoding='utf-8') as stream:
        docstring = stream.read().split('"""')[1]
    needed = set(re.findall(r'ros-jazzy-[a-z-]+[a-z]', docstring))
    line = recipe_block('sudo apt install ')
    assert len(needed) == 6 and set(line.split()[3:]) == needed


def test_the_recipe_s_parameters_are_the_example_s_on_the_simulator_s_port():
    sed = recipe_block("sed 's|")
    old, new = sed.split("'")[1].split('|')[1:3]
    assert sed.split('"')[1].endswith('/config/ros2_control/drive_bridge.yaml')
    with open(os.path.join(EXAMPLE, 'drive_bridge.yaml'), encoding='utf-8') as stream:
        text = stream.read()
    assert text.count(old) == 1
    parameters = dict(yaml.safe_load(text.replace(old, new))['/**/drive_bridge']
                      ['ros__parameters'])
    names = parameters['devices']
    built = config.build_config(parameters, {name: parameters.pop(name) for name in names})
    assert built.link.port == new == recipe_block('drive_bridge_sim ').split('--link ')[1]
    simulated = re.findall(r'--device fc51:(\d+)', recipe_block('drive_bridge_sim '))
    assert sorted(device.address for device in built.devices) == [int(a) for a in simulated]
    pace = recipe_block('drive_bridge_sim ').split('--pace ')[1].split()[0]
    assert pace == f'{built.link.baudrate}:{built.link.parity}:1'
    assert built.link.protocol == 'fc_protocol' and '--protocol fc_protocol' in \
        recipe_block('drive_bridge_sim ')
    launch = recipe_block('ros2 launch ')
    assert launch.split()[2:4] == ['drive_bridge', 'two_wheel_base.launch.py']
    assert 'bridge_params:=/tmp/base_sim.yaml' in launch and '> /tmp/base_sim.yaml' in sed
