"""The node with an FC 51 and an MCD 500 on one simulated bus, driven through rclpy."""

import math

from diagnostic_msgs.msg import DiagnosticStatus
from drive_bridge.sim.devices import make_sim_server
import pytest
from ros_helpers import running_node, serving

# One worker runs this module's tests: its node, a module fixture, then starts once, not
# once on every worker that takes one of them.
pytestmark = pytest.mark.xdist_group('fc_node')

DEVICES = {
    'conv': {'family': 'fc', 'model': 'fc51', 'address': 1, 'poll_rate': 20.0,
             'speed_reference': 40.0, 'comms_timeout': 6.7, 'comms_timeout_function': 2},
    'main': {'family': 'mcd', 'model': 'mcd500', 'address': 20, 'poll_rate': 5.0},
}


@pytest.fixture(scope='module')
def sim():
    with serving(make_sim_server({1: 'fc51', 20: 'mcd500'},
                                 # 4 s to 40 %: 'starting' is seen even when a loaded machine
                                 # holds this process's simulator thread up for a second
                                 settings={'fc': {'ramp_up_s': 10.0, 'ramp_down_s': 1.0,
                                                  'quick_stop_ramp_s': 0.3}})) as server:
        yield server


@pytest.fixture(scope='module')
def node(sim, tmp_path_factory):
    with running_node(tmp_path_factory.mktemp('params') / 'fc.yaml',
                      {'port': sim.pty_path, 'parity': 'N', 'timeout': 0.2,
                       'backoff_max': 2.0, 'diagnostics_period': 0.5}, DEVICES,
                      drives=['conv'], ready=['conv']) as client:
        yield client


@pytest.fixture
def drive(sim, node):
    """Yield the simulated FC 51; stop and reset it after each test."""
    model = sim.devices[1].model
    yield model
    node.set_parameter('conv.reference_timeout', 0.0)
    node.set_parameter('conv.speed_reference', 40.0)
    with sim.lock:
        model.local_mode = False
    assert node.spin_until(lambda: 'local operation' not in (  # the bridge has seen it too
        node.diagnostics('conv') or DiagnosticStatus()).message)
    if model.tripped or model.output_pct:
        node.call('conv', 'reset')
        node.call('conv', 'coast_stop')
    assert node.wait_state('conv', 'ready')


def feedback(node):
    values = node.values('conv', 'speed_feedback')
    return values[-1] if values else None


def test_start_at_40_percent_then_reverse_then_quick_stop(node, drive):
    response = node.call('conv', 'start')
    assert response.success and response.message == 'start acknowledged by conv (address 1)'
    assert node.wait_state('conv', 'running')
    assert drive.reference_word == 0x1999
    # Topics arrive independently: wait for the feedback rather than read it with the state.
    assert node.spin_until(lambda: abs(feedback(node) - 40.0) < 0.01)
    assert 'starting' in node.values('conv', 'state')
    assert node.spin_until(lambda: node.values('conv', 'motor_current')[-1] > 0.5)
    node.publish_reference('conv', -40.0)
    assert node.spin_until(lambda: feedback(node) < -39.9)
    assert drive.reference_word == 0xE667  # two's complement of 0x1999
    assert node.call('conv', 'quick_stop').success
    assert drive.control_word == 0x042C
    assert node.wait_state('conv', 'ready')
    assert node.values('conv', 'state')[-2:] == ['stopping', 'ready']


def test_speed_reference_parameter_and_coast(node, drive):
    assert node.set_parameter('conv.speed_reference', 25.0).successful
    assert node.call('conv', 'start').success
    assert node.wait_state('conv', 'running')
    assert drive.reference_word == 0x1000
    assert node.call('conv', 'coast_stop').success
    assert drive.control_word == 0x0434 and drive.output_pct == 0.0
    assert node.wait_state('conv', 'ready')


@pytest.mark.parametrize('value', [250.0, -200.5, math.nan, math.inf])
def test_bad_speed_reference_parameter_is_refused(node, drive, value):
    result = node.set_parameter('conv.speed_reference', value)
    assert not result.successful and 'conv.speed_reference' in result.reason


def test_bad_speed_reference_messages_are_not_sent(node, drive):
    assert node.call('conv', 'start').success
    assert node.wait_state('conv', 'running')
    for bad in (math.nan, math.inf, 300.0):
        node.publish_reference('conv', bad)
    node.publish_reference('conv', 20.0)
    assert node.spin_until(lambda: drive.reference_word == 0x0CCC)
    assert node.spin_until(lambda: {kv.key: kv.value for kv in (
        node.diagnostics('conv') or DiagnosticStatus()).values}.get(
            'rejected_references') == '3')
    assert node.call('conv', 'stop').success


def test_alarm_trip_then_reset(node, drive, sim):
    with sim.lock:
        drive.trip(5, sim.clock())
    assert node.wait_state('conv', 'tripped')
    assert node.spin_until(lambda: node.values('conv', 'trip')[-1:] == ['Over current'])
    assert node.spin_until(lambda: node.values('conv', 'trip_code')[-1:] == [13])
    assert node.spin_until(lambda: node.values('conv', 'alarm_word')[-1:] == [32])
    assert node.spin_until(lambda: (node.diagnostics('conv') or DiagnosticStatus()).level ==
                           DiagnosticStatus.ERROR)
    refused = node.call('conv', 'start')
    assert not refused.success and 'reset it first' in refused.message
    assert node.call('conv', 'reset').success
    assert node.wait_state('conv', 'ready')
    assert node.spin_until(lambda: node.values('conv', 'trip')[-1:] == [''])
    assert drive.output_pct == 0.0  # a reset does not restart the motor


def test_deadman_ramp_stops_without_reference_messages(node, drive):
    assert node.set_parameter('conv.reference_timeout', 0.5).successful
    assert node.call('conv', 'start').success
    for _ in range(15):  # 1.5 s of messages every 0.1 s keep it running
        node.publish_reference('conv', 30.0)
        node.spin_until(lambda: False, 0.1)
    assert drive.control_word == 0x047C and drive.reference_word == 0x1333
    assert node.wait_state('conv', 'ready', 5.0)
    assert drive.control_word == 0x043C


def test_local_operation_is_refused_with_its_reason(node, drive, sim):
    with sim.lock:
        drive.local_mode = True
    assert node.spin_until(lambda: 'local operation' in (
        node.diagnostics('conv') or DiagnosticStatus()).message)
    drive.control_words_received.clear()
    response = node.call('conv', 'start')
    assert not response.success and 'local operation' in response.message
    assert 'nothing sent' in response.message
    # The keepalive goes on rewriting the last word (a stop); no start word went out.
    assert 0x047C not in drive.control_words_received


def test_setup_writes_and_diagnostics(node, drive):
    # written once the drive is online (the test may be the module's first on its worker)
    assert node.spin_until(lambda: drive.parameters[803] == 67 and drive.parameters[804] == 2)
    assert node.wait_fresh_diagnostics()  # published after the writes: the drive's values now
    status = node.diagnostics('conv')
    assert status.hardware_id == 'fc fc51 address 1'
    values = {kv.key: kv.value for kv in status.values}
    for key in ('drive_type', 'software_version', 'bus_control', 'speed_feedback_pct',
                'control_word_sent', 'reference_word', 'deadman_stops', 'frequency'):
        assert key in values
    assert values['drive_type'].startswith('FC-051')
