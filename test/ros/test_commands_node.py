"""
The commands node: where ``~/joint_commands`` and ``<name>/speed_reference`` are subscribed.

They live on ``<node>_commands`` beside the node, in its namespace, under the names the
node itself resolves: the contract's names, with the namespace, a renamed node and
``-r`` remappings applied. The references are read from the simulated drives.
"""

from contextlib import contextmanager

from drive_bridge.config.params_file import write_params_file
from drive_bridge.sim.devices import make_sim_server
import pytest
from rclpy.qos import QoSProfile, ReliabilityPolicy
from ros_helpers import RosClient, serving, start_node, stop_node
from sensor_msgs.msg import JointState
from std_msgs.msg import Float32

NAMESPACE = '/line1'
DEVICES = {
    'wheel': {'family': 'fc', 'model': 'fc51', 'address': 1, 'poll_rate': 20.0,
              'velocity_scale': 20.0},
    'conv': {'family': 'fc', 'model': 'fc51', 'address': 2, 'poll_rate': 20.0},
}
REMAPS = ('__node:=left_bus', '/line1/left_bus/joint_commands:=/line1/cmd',
          'conv/speed_reference:=conv/ref')


@pytest.fixture(scope='module')
def sim():
    with serving(make_sim_server({1: 'fc51', 2: 'fc51'})) as server:
        yield server


@contextmanager
def renamed_node(sim, path):
    """Run the node as ``left_bus`` in ``/line1`` with REMAPS; yield a client once ready."""
    params = write_params_file(str(path), {'port': sim.pty_path, 'parity': 'N',
                                           'timeout': 0.5}, DEVICES, node_key='/**/left_bus')
    process = start_node(params, NAMESPACE, remaps=REMAPS)
    client = RosClient(list(DEVICES), namespace=NAMESPACE, drives=list(DEVICES))
    try:
        for name in DEVICES:
            assert client.wait_state(name, 'ready', 15.0), stop_node(process)
        yield client
    finally:
        client.close()
        print(stop_node(process)[1])


def subscribers(client, topic):
    return sorted((info.node_name, info.node_namespace)
                  for info in client.node.get_subscriptions_info_by_topic(topic))


def test_the_command_subscriptions_follow_namespace_node_name_and_remaps(sim, tmp_path):
    with renamed_node(sim, tmp_path / 'names.yaml') as client:
        node = client.node
        commands = ('left_bus_commands', NAMESPACE)
        assert client.spin_until(
            lambda: commands in node.get_node_names_and_namespaces(), 15.0)
        assert ('left_bus', NAMESPACE) in node.get_node_names_and_namespaces()
        for topic in ('/line1/cmd', '/line1/conv/ref', '/line1/wheel/speed_reference'):
            assert client.spin_until(lambda: subscribers(client, topic) == [commands]), topic
        assert subscribers(client, '/line1/left_bus/joint_commands') == []
        assert subscribers(client, '/line1/conv/speed_reference') == []
        # Through the remapped names to the drives (a stop first: from a first command on,
        # every poll writes the control word in force with the reference).
        for device in DEVICES:
            assert client.call(device, 'stop').success
        joints = node.create_publisher(JointState, '/line1/cmd',
                                       QoSProfile(depth=1,
                                                  reliability=ReliabilityPolicy.RELIABLE))
        reference = node.create_publisher(Float32, '/line1/conv/ref', 10)
        wheel, conv = sim.devices[1].model, sim.devices[2].model

        def sent() -> bool:
            joints.publish(JointState(name=['wheel'], velocity=[10.0]))  # 50 %
            reference.publish(Float32(data=25.0))
            return wheel.reference_word == 0x2000 and conv.reference_word == 0x1000

        assert client.spin_until(sent, 10.0), (hex(wheel.reference_word),
                                               hex(conv.reference_word))
        assert wheel.output_pct == 0.0 and conv.output_pct == 0.0  # references start nothing
