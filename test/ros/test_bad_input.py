"""
Bad input through ROS, as a table: each gets a clear refusal and nothing reaches a device.

The drive is running during the table, so its keepalive is on the wire: "nothing sent"
means its control word and speed reference stay as they were, and the starters receive
no command.
"""

import math

from diagnostic_msgs.msg import DiagnosticStatus
from drive_bridge.sim.devices import make_sim_server
import pytest
from ros_helpers import running_node, serving, start_node, stop_node

# One worker runs this module's tests: its node, a module fixture, then starts once, not
# once on every worker that takes one of them.
pytestmark = pytest.mark.xdist_group('bad_input')

DEVICES = {
    'conv': {'family': 'fc', 'model': 'fc51', 'address': 1, 'poll_rate': 20.0,
             'speed_reference': 40.0, 'comms_timeout': 10.0},
    'watch': {'family': 'mcd', 'model': 'mcd500', 'address': 20, 'allow_control': False},
    'gone': {'family': 'mcd', 'model': 'mcd500', 'address': 30},  # nobody answers
}
REFERENCE_40_PCT = 0x1999


@pytest.fixture(scope='module')
def sim():
    with serving(make_sim_server({1: 'fc51', 20: 'mcd500'})) as server:
        yield server


@pytest.fixture(scope='module')
def node(sim, tmp_path_factory):
    with running_node(tmp_path_factory.mktemp('params') / 'bad_input.yaml',
                      {'port': sim.pty_path, 'parity': 'N', 'timeout': 0.3,
                       'diagnostics_period': 0.2}, DEVICES, drives=['conv'],
                      ready=['conv']) as client:
        assert client.wait_state('gone', 'offline', 15.0)
        assert client.call('conv', 'start').success
        assert client.wait_state('conv', 'running')
        yield client
        client.call('conv', 'coast_stop')


def what_devices_hold(sim):
    """Return what the devices were told so far: the drive's words, the starters' commands."""
    with sim.lock:
        drive = sim.devices[1].model
        return (drive.control_word, drive.reference_word,
                list(sim.devices[20].model.commands_received))


def rejected_references(node):
    status = node.diagnostics('conv') or DiagnosticStatus()
    return int({kv.key: kv.value for kv in status.values}.get('rejected_references', -1))


@pytest.mark.parametrize('value', [math.nan, math.inf, -math.inf, 200.0, -200.01, 1e30])
def test_bad_speed_reference_message(node, sim, value):
    before, rejected = what_devices_hold(sim), rejected_references(node)
    node.publish_reference('conv', value)
    node.messages['/diagnostics'].clear()
    assert node.spin_until(lambda: rejected_references(node) == rejected + 1)
    assert what_devices_hold(sim) == before
    assert before[1] == REFERENCE_40_PCT


@pytest.mark.parametrize('name, value, reason', [
    ('conv.speed_reference', math.nan, 'conv.speed_reference'),
    ('conv.speed_reference', math.inf, 'conv.speed_reference'),
    ('conv.speed_reference', 250.0, 'conv.speed_reference out of range'),
    ('conv.poll_rate', -1.0, 'conv.poll_rate out of range Min: 0.1'),
    ('conv.poll_rate', True, "'conv.poll_rate' = True has the wrong type"),
    # 10 s between polls (and the polls under way) exceed par. 8-03 (the gap at 20 Hz: 8.5 s)
    ('conv.poll_rate', 0.1, 'poll_rate not changed: conv.comms_timeout 10 s is below 14.09 s'),
    ('conv.reference_timeout', -1.0, 'conv.reference_timeout out of range'),
    ('ghost.poll_rate', 5.0, 'undeclared parameter'),  # no such device (rclpy's words)
])
def test_bad_parameter(node, sim, name, value, reason):
    before = what_devices_hold(sim)
    result = node.set_parameter(name, value)
    assert not result.successful
    print(f'{name} = {value}: {result.reason}')
    assert reason in result.reason
    assert what_devices_hold(sim) == before


@pytest.mark.parametrize('device, command, reason', [
    ('watch', 'start', 'watch is monitor only (allow_control is false): nothing sent'),
    ('watch', 'reset', 'monitor only'),
    ('gone', 'start', 'gone is offline'),
    ('gone', 'stop', 'nothing sent'),
])
def test_command_that_cannot_be_sent(node, sim, device, command, reason):
    before = what_devices_hold(sim)
    response = node.call(device, command)
    assert not response.success and reason in response.message
    assert what_devices_hold(sim) == before


def test_the_node_survived_the_table(node):
    assert node.state('conv') == 'running'
    assert node.call('conv', 'stop').success
    assert node.wait_state('conv', 'ready')
    assert node.call('conv', 'start').success


@pytest.mark.parametrize('content, expected', [
    ('/**/drive_bridge:\n  ros__parameters:\n    devices: [a\n', 'is not valid YAML at line 4'),
    ('just text\n', 'must map a node name'),
    ('/**/drive_bridge:\n  ros__parameters:\n    devices: []\n', "'devices' is empty"),
    ('/**/drive_bridge:\n  ros__parameters:\n    devices: [conv]\n    conv:\n'
     '      family: fc\n      address: 1\n      comms_timeout: 0.1\n',
     'conv.comms_timeout 0.1 s is below'),
    (None, 'cannot read the parameters file'),
])
def test_malformed_parameter_files_stop_the_node_with_one_line(tmp_path, content, expected):
    path = tmp_path / 'params.yaml'
    if content is not None:
        path.write_text(content)
    process = start_node(str(path))
    process.wait(timeout=30.0)  # it stops by itself
    code, output = stop_node(process)
    assert code == 2, output
    assert expected in output and 'Traceback' not in output, output
