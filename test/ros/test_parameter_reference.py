"""
The manual's configuration reference against the parameters the node declares.

Every parameter the node declares is in it, and it has none the node does not declare. The
reference (docs/configuration.md) is built from docs/_ext/parameter_reference.py. Each
protocol declares its own bus parameters, each family its own device parameters, so three
nodes between them declare everything: Modbus RTU with a device of every family that runs on
it, AP ASCII, and the FC protocol. Their ports do not exist: the node declares its
parameters at configure whatever the line does.
"""

import os
import time

from docs_helpers import parameter_reference
from drive_bridge.config.node_parameters import ROS_PARAMETERS
from rcl_interfaces.srv import ListParameters
import rclpy
from ros_helpers import node_output, start_node, stop_node, write_params

LVSG = {'family': 'lvsg', 'model': 'mcd202', 'address': 2, 'gateway_input_register': 0,
        'gateway_output_register': 100}
NODES = {
    'modbus_rtu': {'starter': {'family': 'mcd', 'model': 'mcd500', 'address': 20},
                   'conveyor': {'family': 'fc', 'address': 1},
                   'fan': {'family': 'vlt', 'model': 'vlt6000', 'address': 5},
                   'mixer': LVSG},
    'ap_ascii': {'starter': {'family': 'mcd', 'model': 'mcd3000', 'address': 21}},
    'fc_protocol': {'conveyor': {'family': 'fc', 'address': 1},
                    'fan': {'family': 'vlt', 'model': 'vlt5000', 'address': 6}},
}
FRAMING = {'ap_ascii': {'parity': 'N', 'timeout': 0.5}}


def declared_parameters(protocol, devices, tmp_path):
    """Return the names the node declares for ``devices`` on ``protocol``."""
    bus = dict(protocol=protocol, port=str(tmp_path / 'no_such_port'), **FRAMING.get(
        protocol, {}))
    process = start_node(write_params(tmp_path / f'{protocol}.yaml', bus, devices))
    node = rclpy.create_node(f'reference_client_{os.getpid()}')
    try:
        deadline = time.monotonic() + 30.0
        while 'active: commands enabled' not in node_output(process):
            assert process.poll() is None and time.monotonic() < deadline, \
                stop_node(process)[1]
            time.sleep(0.05)
        client = node.create_client(ListParameters, '/drive_bridge/list_parameters')
        assert client.wait_for_service(timeout_sec=10.0)
        future = client.call_async(ListParameters.Request())
        rclpy.spin_until_future_complete(node, future, timeout_sec=10.0)
        assert future.done(), 'list_parameters did not answer'
        return set(future.result().result.names)
    finally:
        node.destroy_node()
        stop_node(process)


def test_the_reference_lists_exactly_the_parameters_the_node_declares(tmp_path):
    declared = {'bus': set(), 'device': set()}
    for protocol, devices in NODES.items():
        names = declared_parameters(protocol, devices, tmp_path)
        for name in names - set(ROS_PARAMETERS):
            device, _, setting = name.partition('.')
            if setting:
                assert device in devices, name
                declared['device'].add(setting)
            else:
                declared['bus'].add(name)
    reference = parameter_reference().reference_names()
    assert declared['bus'] - reference['bus'] == set(), 'declared, not in the reference'
    assert declared['device'] - reference['device'] == set(), 'declared, not in the reference'
    assert reference['bus'] - declared['bus'] == set(), 'in the reference, never declared'
    assert reference['device'] - declared['device'] == set(), \
        'in the reference, never declared'
