"""
Adversarial bad input through ROS, beyond ``test_bad_input.py``'s table.

The node runs in a subprocess; rclpy clients send it what a confused or hostile peer could:
bytes that are no ``Float32`` on ``<name>/speed_reference``, JointStates with a joint named
twice or nothing at all, parameter changes of the wrong kind (a parameter deleted with type
NOT_SET, arrays, an integer for a double, several in one non-atomic call), writes aimed at a
monitor-only drive, and replies on the wire that are valid frames with absurd contents or
of the wrong function. What the devices received is read from the simulator (its frame
record and its models), never from the bridge's own word; the node must still serve after
each.
"""

import math
import struct
import subprocess
import sys

from diagnostic_msgs.msg import DiagnosticStatus
from drive_bridge.protocol.crc import append_crc
from drive_bridge.sim.devices import make_sim_server
import fork_server
import pytest
from rcl_interfaces.msg import Parameter as ParameterMsg, ParameterType, ParameterValue
from rcl_interfaces.srv import (
    DescribeParameters, GetParameters, SetParameters, SetParametersAtomically)
import rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy
from ros_helpers import node_output, running_node, serving, start_node, stop_node
from sensor_msgs.msg import JointState
from std_msgs.msg import Float32

pytestmark = pytest.mark.xdist_group('adversarial_input')

SCALE = 20.0  # rad/s at 100 %
DEVICES = {
    'conv': {'family': 'fc', 'model': 'fc51', 'address': 1, 'poll_rate': 20.0,
             'velocity_scale': SCALE, 'joint_name': 'conv_joint'},
    'mon': {'family': 'fc', 'model': 'fc51', 'address': 2, 'poll_rate': 20.0,
            'allow_control': False},
    'soft': {'family': 'mcd', 'model': 'mcd500', 'address': 20, 'poll_rate': 20.0},
}


WRITE_FUNCTIONS = (0x05, 0x06, 0x0F, 0x10)
REFERENCE_10_PCT = 0x0666  # 2 rad/s on conv
REFERENCE_15_PCT = 0x0999  # 3 rad/s on conv


@pytest.fixture(scope='module')
def sim():
    server = make_sim_server({1: 'fc51', 2: 'fc51', 20: 'mcd500'})
    server.record_frames = True
    with serving(server):
        yield server


@pytest.fixture(scope='module')
def node(sim, tmp_path_factory):
    with running_node(tmp_path_factory.mktemp('params') / 'adversarial.yaml',
                      {'port': sim.pty_path, 'parity': 'N', 'timeout': 0.3,
                       'offline_after': 2, 'backoff_max': 0.5, 'diagnostics_period': 0.2},
                      DEVICES, drives=['conv', 'mon'], ready=list(DEVICES)) as client:
        # A stop: conv's stop image is kept alive on the wire with the reference in force.
        assert client.call('conv', 'stop').success
        client.raw_reference = client.node.create_publisher(
            Float32, '/conv/speed_reference', 10)
        client.joint_commands = client.node.create_publisher(
            JointState, '/drive_bridge/joint_commands',
            QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE))
        client.get_client = client.node.create_client(GetParameters,
                                                      '/drive_bridge/get_parameters')
        client.atomic_client = client.node.create_client(
            SetParametersAtomically, '/drive_bridge/set_parameters_atomically')
        yield client


@pytest.fixture
def conv_holds_10_pct(node, sim):
    """Give conv a 10 % reference (2 rad/s) and wait until the drive holds it."""
    assert drive(sim, 1).reference_word == 0
    node.publish_reference('conv', 10.0)
    assert node.spin_until(lambda: drive(sim, 1).reference_word == REFERENCE_10_PCT)
    yield drive(sim, 1)
    node.publish_reference('conv', 0.0)
    assert node.spin_until(lambda: drive(sim, 1).reference_word == 0)


def drive(sim, unit):
    return sim.devices[unit].model


def writes_to(sim, unit):
    """Return every write request the simulated line carried to ``unit`` so far."""
    with sim.lock:
        frames = list(sim.stats.frames)
    return [frame for frame in frames if frame[0] == unit and frame[1] in WRITE_FUNCTIONS]


def requests_to(sim, unit):
    with sim.lock:
        return sum(1 for frame in sim.stats.frames if frame[0] == unit)


def diagnostic_values(node, device):
    status = node.diagnostics(device) or DiagnosticStatus()
    return {kv.key: kv.value for kv in status.values}


def counter(node, device, key):
    return int(diagnostic_values(node, device).get(key, -1))


def joint_counters(node):
    for array in reversed(node.messages['/diagnostics']):
        for status in array.status:
            if status.name == 'drive_bridge: ~/joint_commands':
                return {kv.key: kv.value for kv in status.values}
    return {}


def alive_and_serving(node, sim):
    """Assert that the node process lives, answers a parameter call and takes a reference."""
    assert node.process.poll() is None, node_output(node.process)[-3000:]
    assert node.set_parameter('conv.poll_rate', 20.0).successful
    node.publish_reference('conv', 15.0)
    assert node.spin_until(lambda: drive(sim, 1).reference_word == REFERENCE_15_PCT)
    node.publish_reference('conv', 0.0)
    assert node.spin_until(lambda: drive(sim, 1).reference_word == 0)
    assert 'Traceback' not in node_output(node.process)


def set_raw(node, parameters, atomic=False):
    """Send (name, ParameterValue) pairs as they are; return the results (or the result)."""
    messages = [ParameterMsg(name=name, value=value) for name, value in parameters]
    if atomic:
        client, request = node.atomic_client, SetParametersAtomically.Request(
            parameters=messages)
    else:
        client, request = node.parameters, SetParameters.Request(parameters=messages)
    assert client.wait_for_service(timeout_sec=5.0)
    future = client.call_async(request)
    rclpy.spin_until_future_complete(node.node, future, timeout_sec=5.0)
    assert future.done(), 'the parameter service did not answer'
    return future.result().result if atomic else future.result().results


def get_values(node, names):
    assert node.get_client.wait_for_service(timeout_sec=5.0)
    future = node.get_client.call_async(GetParameters.Request(names=list(names)))
    rclpy.spin_until_future_complete(node.node, future, timeout_sec=5.0)
    assert future.done()
    return list(future.result().values)


def double(value):
    return ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=value)


# -- bytes that are no Float32 on <name>/speed_reference ---------------------------------
# Fast DDS pads a payload to a multiple of 4 bytes with zeros on its way to another process:
# 6 bytes (the header and half a float) arrive as a whole Float32 of about 2e-41, which is a
# valid reference of 0 %, so they are not here. These stay bytes that are no Float32.
NOT_A_FLOAT32 = {
    'header only, no float': b'\x00\x01\x00\x00',
    'one byte': b'\x01',
}
GOOD_CDR_NAN = b'\x00\x01\x00\x00' + struct.pack('<f', math.nan)


@pytest.mark.parametrize('label', list(NOT_A_FLOAT32))
def test_bytes_that_are_no_float32_on_speed_reference_send_nothing(
        node, sim, conv_holds_10_pct, label):
    conv = conv_holds_10_pct
    words = len(conv.control_words_received)
    assert node.wait_fresh_diagnostics()
    rejected = counter(node, 'conv', 'rejected_references')
    node.raw_reference.publish(NOT_A_FLOAT32[label])
    # Then a NaN in good CDR. Both are counted, in order: the bytes have been taken by now.
    node.raw_reference.publish(GOOD_CDR_NAN)
    assert node.spin_until(lambda: counter(node, 'conv', 'rejected_references') == rejected + 2)
    assert node.spin_until(lambda: len(conv.control_words_received) > words + 2)  # polls
    assert conv.reference_word == REFERENCE_10_PCT  # nothing of the bytes reached the drive
    assert all(word == conv.control_words_received[0]
               for word in list(conv.control_words_received)[words:])
    output = node_output(node.process)
    assert 'Traceback' not in output, output[-3000:]
    alive_and_serving(node, sim)


def reference_log_lines(node):
    return [line for line in node_output(node.process).splitlines()
            if 'conv/speed_reference' in line]


def test_bytes_that_are_no_float32_on_speed_reference_get_a_reason(node, conv_holds_10_pct):
    node.spin_until(lambda: False, 1.1)  # the log throttle's period (once a second at most)
    before = len(reference_log_lines(node))
    assert node.wait_fresh_diagnostics()
    rejected = counter(node, 'conv', 'rejected_references')
    node.raw_reference.publish(NOT_A_FLOAT32['header only, no float'])

    def reasons():
        return [line for line in reference_log_lines(node)[before:]
                if 'conv/speed_reference: not a std_msgs/Float32 (' in line]
    said = node.spin_until(lambda: bool(reasons()), 3.0)
    print(reference_log_lines(node)[before:])
    assert said, 'no reason given for bytes that are no Float32'
    assert '): ignored, nothing sent' in reasons()[0], reasons()[0]
    # Counted once, as the bus counts the values it refuses.
    assert node.spin_until(lambda: counter(node, 'conv', 'rejected_references') == rejected + 1)
    assert node.wait_fresh_diagnostics()  # a /diagnostics begun after the count: not twice
    assert counter(node, 'conv', 'rejected_references') == rejected + 1


# -- JointStates that are whole but say nothing, or say it twice --------------------------
def test_an_empty_joint_state_is_counted_and_sends_nothing(node, sim, conv_holds_10_pct):
    conv = conv_holds_10_pct
    assert node.wait_fresh_diagnostics()
    before = int(joint_counters(node).get('messages_without_velocity', 0))
    node.joint_commands.publish(JointState())
    assert node.spin_until(lambda: int(joint_counters(node).get(
        'messages_without_velocity', 0)) == before + 1)
    assert conv.reference_word == REFERENCE_10_PCT
    alive_and_serving(node, sim)


@pytest.mark.parametrize('velocities', [[3.0, math.nan], [3.0, 2.5]],
                         ids=['then NaN', 'then 2.5'])
def test_a_joint_named_twice_in_one_message_is_refused(node, sim, conv_holds_10_pct,
                                                       velocities):
    conv = conv_holds_10_pct
    assert node.wait_fresh_diagnostics()
    before = joint_counters(node)
    words = len(conv.control_words_received)
    node.joint_commands.publish(JointState(name=['conv_joint', 'conv_joint'],
                                           velocity=velocities))
    assert node.spin_until(lambda: int(joint_counters(node).get('messages', 0)) >
                           int(before.get('messages', 0)))
    assert node.spin_until(lambda: len(conv.control_words_received) > words + 2)  # polls
    counted = {key: value for key, value in joint_counters(node).items()
               if key.startswith('messages_') and value != before.get(key)}
    print(f'{velocities}: reference word 0x{conv.reference_word:04X}, counted {counted}')
    assert conv.reference_word == REFERENCE_10_PCT, 'part of a contradictory message was sent'
    assert counted, 'a contradictory message was not counted as ignored'


# -- parameters of the wrong kind -----------------------------------------------------------
@pytest.mark.parametrize('name', ['conv.poll_rate', 'conv.speed_reference', 'mon.allow_control',
                                  'conv.address', 'port'])
def test_a_parameter_deleted_with_type_not_set_is_refused(node, sim, name):
    before = get_values(node, [name])[0]
    results = set_raw(node, [(name, ParameterValue(type=ParameterType.PARAMETER_NOT_SET))])
    print(f'{name} = NOT_SET: {results[0].successful} {results[0].reason!r}')
    assert not results[0].successful and results[0].reason
    assert '\n' not in results[0].reason
    assert get_values(node, [name])[0] == before
    assert writes_to(sim, 2) == []
    alive_and_serving(node, sim)


@pytest.mark.parametrize('value', [
    ParameterValue(type=ParameterType.PARAMETER_DOUBLE_ARRAY, double_array_value=[5.0]),
    ParameterValue(type=ParameterType.PARAMETER_BYTE_ARRAY, byte_array_value=[b'\x01']),
    ParameterValue(type=ParameterType.PARAMETER_STRING, string_value='5.0'),
    ParameterValue(type=ParameterType.PARAMETER_INTEGER, integer_value=2 ** 63 - 1),
], ids=['double array', 'byte array', 'string', 'int64 max'])
def test_a_value_of_the_wrong_kind_is_refused_in_one_line(node, sim, value):
    results = set_raw(node, [('conv.poll_rate', value)])
    print(f'conv.poll_rate = {value}: {results[0].reason!r}')
    assert not results[0].successful and results[0].reason and '\n' not in results[0].reason
    assert get_values(node, ['conv.poll_rate'])[0].double_value == 20.0
    alive_and_serving(node, sim)


def test_a_parameter_of_no_known_type_is_answered(node, sim):
    results = set_raw(node, [('conv.poll_rate', ParameterValue(type=42)),
                             ('conv.poll_rate', double(20.0))])
    assert not results[0].successful and '\n' not in results[0].reason
    assert results[1].successful  # the others of a non-atomic set are taken as before
    result = set_raw(node, [('conv.poll_rate', double(25.0)),
                            ('conv.speed_reference', ParameterValue(type=42))], atomic=True)
    assert not result.successful and "'conv.speed_reference'" in result.reason
    assert get_values(node, ['conv.poll_rate'])[0].double_value == 20.0


def descriptor_type(node, name):
    client = node.node.create_client(DescribeParameters, '/drive_bridge/describe_parameters')
    try:
        assert client.wait_for_service(timeout_sec=5.0)
        future = client.call_async(DescribeParameters.Request(names=[name]))
        rclpy.spin_until_future_complete(node.node, future, timeout_sec=5.0)
        assert future.done()
        return future.result().descriptors[0].type
    finally:
        node.node.destroy_client(client)


def ctl(*args):
    return fork_server.run([sys.executable, '-m', 'drive_bridge.ros.ctl.cli', *args],
                           capture_output=True, text=True, timeout=60, stdin=subprocess.DEVNULL)


def test_an_atomic_change_refused_for_another_parameter_leaves_the_declared_type(node, sim):
    """The read-only address is refused by rclpy before the node sees poll_rate's value."""
    result = set_raw(node, [
        ('conv.poll_rate', ParameterValue(type=ParameterType.PARAMETER_STRING,
                                          string_value='fast')),
        ('conv.address', ParameterValue(type=ParameterType.PARAMETER_INTEGER,
                                        integer_value=5))], atomic=True)
    print(f'poll_rate fast + address 5 atomically: {result.successful} {result.reason!r}')
    assert not result.successful and '\n' not in result.reason
    assert descriptor_type(node, 'conv.poll_rate') == ParameterType.PARAMETER_DOUBLE


def test_a_refused_value_of_the_wrong_type_leaves_the_declared_type(node, sim):
    refused = node.set_parameter('conv.poll_rate', 'fast')
    assert not refused.successful
    declared = descriptor_type(node, 'conv.poll_rate')
    result = ctl('param', 'set', 'conv.poll_rate', '10')
    print(f'declared type after the refusal: {declared}; ctl: {result.returncode} '
          f'{result.stdout!r} {result.stderr!r}')
    assert node.set_parameter('conv.poll_rate', 20.0).successful
    assert declared == ParameterType.PARAMETER_DOUBLE
    assert result.returncode == 0 and result.stdout == 'conv.poll_rate = 10.0 (double)\n'


def test_ctl_refuses_a_reference_that_is_no_plain_number(node, sim, conv_holds_10_pct):
    conv = conv_holds_10_pct
    result = ctl('reference', 'conv', '1_5')
    print(f'ctl reference conv 1_5: {result.returncode} {result.stdout!r} {result.stderr!r}')
    written = node.spin_until(lambda: conv.reference_word == 0x0999, 2.0)  # 15 %
    node.publish_reference('conv', 10.0)
    assert node.spin_until(lambda: conv.reference_word == REFERENCE_10_PCT)
    assert not written, 'the text 1_5 reached the drive as 15 %'
    assert result.returncode == 2 and result.stderr.count('\n') == 1, result.stderr


def test_an_integer_for_a_double_parameter_is_refused_as_the_docs_say(node, sim):
    """docs/configuration.md: 'a double parameter set with an integer is refused'."""
    result = set_raw(node, [('conv.poll_rate', ParameterValue(
        type=ParameterType.PARAMETER_INTEGER, integer_value=10))])[0]
    after = get_values(node, ['conv.poll_rate'])[0]
    set_raw(node, [('conv.poll_rate', double(20.0))])
    print(f'conv.poll_rate = 10 (integer): {result.successful} {result.reason!r}; '
          f'then read back as type {after.type}')
    assert not result.successful, 'an integer was taken for a double parameter'


def test_a_non_atomic_set_with_one_bad_value_refuses_that_one_in_one_line(node, sim):
    """Set several with SetParameters (ros2 param set's service): each is taken or refused."""
    results = set_raw(node, [('conv.reference_timeout', double(2.5)),
                             ('conv.speed_reference', double(math.nan)),
                             ('mon.speed_reference', double(50.0))])
    print([(result.successful, result.reason) for result in results])
    assert not results[1].successful and '\n' not in results[1].reason
    values = get_values(node, ['conv.reference_timeout', 'conv.speed_reference'])
    set_raw(node, [('conv.reference_timeout', double(0.0))])
    assert results[0].successful and values[0].double_value == 2.5
    assert not math.isnan(values[1].double_value)
    assert writes_to(sim, 2) == []
    alive_and_serving(node, sim)


def test_an_atomic_set_naming_one_parameter_twice_takes_the_last_or_nothing(node, sim):
    result = set_raw(node, [('conv.speed_reference', double(12.5)),
                            ('conv.speed_reference', double(math.inf))], atomic=True)
    assert not result.successful and '\n' not in result.reason
    assert drive(sim, 1).reference_word != 0x0800  # 12.5 %: not sent
    result = set_raw(node, [('conv.speed_reference', double(math.inf)),
                            ('conv.speed_reference', double(12.5))], atomic=True)
    print(f'[inf, 12.5] atomically: {result.successful} {result.reason!r}')
    assert not result.successful, 'a bad value in an atomic set was overwritten and taken'
    node.spin_until(lambda: drive(sim, 1).reference_word == 0x0800, 1.0)
    assert drive(sim, 1).reference_word != 0x0800
    alive_and_serving(node, sim)


# -- a monitor-only drive: nothing reaches it, from any ROS path ---------------------------
def test_nothing_reaches_a_monitor_only_drive_from_any_ros_path(node, sim):
    mon = drive(sim, 2)
    polled = requests_to(sim, 2)
    for name, value in (('mon.speed_reference', 50.0), ('mon.reference_timeout', 0.5),
                        ('mon.stop_on_shutdown', True), ('mon.poll_rate', 50.0)):
        print(f'{name} = {value}: {node.set_parameter(name, value)}')
    node.publish_reference('mon', 50.0)
    for command in ('start', 'stop', 'quick_stop', 'coast_stop', 'reset'):
        response = node.call('mon', command)
        assert not response.success and 'nothing sent' in response.message
    assert node.spin_until(lambda: requests_to(sim, 2) > polled + 20)  # a second of polls
    assert writes_to(sim, 2) == []
    assert mon.control_word == 0 and mon.reference_word == 0
    set_raw(node, [('mon.poll_rate', double(20.0)), ('mon.speed_reference', double(0.0))])


def test_use_sim_time_without_a_clock_does_not_silence_diagnostics(node, sim):
    result = node.set_parameter('use_sim_time', True)
    try:
        count = len(node.messages['/diagnostics'])
        published = node.spin_until(lambda: len(node.messages['/diagnostics']) > count + 1,
                                    2.0)  # 10 periods
    finally:
        assert node.set_parameter('use_sim_time', False).successful
    print(f'use_sim_time true: {result.successful} {result.reason!r}; '
          f'/diagnostics within 2 s: {published}')
    assert published or not result.successful, '/diagnostics stopped without a word'
    assert node.wait_fresh_diagnostics()


# -- the wire: valid frames with absurd contents, or of another function --------------------
def all_bits_set(unit, functions=(0x03,)):
    """Return a reply hook: every bit a read of ``unit`` (by ``functions``) returns is 1."""
    def hook(reply_unit, data):
        if reply_unit == unit and data[1] in functions:
            return append_crc(data[:3] + b'\xff' * data[2])
        return data
    return hook


def another_function(unit):
    """Return a reply hook: ``unit``'s reads are answered as function 0x04, CRC valid."""
    def hook(reply_unit, data):
        if reply_unit == unit and data[1] in (0x01, 0x03):
            return append_crc(bytes([data[0], 0x04]) + data[2:-2])
        return data
    return hook


@pytest.fixture
def hooked(sim, node):
    yield sim
    sim.reply_hook = None
    for device in DEVICES:
        assert node.wait_state(device, 'ready', 15.0), device


def test_a_starter_whose_registers_all_read_0xffff(node, hooked):
    sim = hooked
    node.messages['soft/motor_current'].clear()
    sim.reply_hook = all_bits_set(20)
    assert node.spin_until(lambda: node.state('soft') != 'ready', 5.0)
    assert node.wait_fresh_diagnostics()
    status = node.diagnostics('soft')
    currents = node.values('soft', 'motor_current')
    print(f'soft: state {node.state("soft")}, diagnostics {status.level!r} {status.message!r}, '
          f'currents {currents[-3:]}')
    assert status.level in (DiagnosticStatus.WARN, DiagnosticStatus.ERROR)
    assert status.message and '\n' not in status.message
    assert all(math.isfinite(value) for value in currents)
    sim.reply_hook = None
    assert node.wait_state('soft', 'ready', 10.0)
    alive_and_serving(node, sim)


def test_replies_of_another_function_publish_nothing_stale(node, hooked):
    sim = hooked
    errors = counter(node, 'soft', 'errors')
    sim.reply_hook = another_function(20)
    assert node.wait_state('soft', 'offline', 10.0)
    node.messages['soft/motor_current'].clear()
    node.messages['soft/status_word'].clear()
    assert node.wait_fresh_diagnostics()
    assert node.spin_until(lambda: counter(node, 'soft', 'errors') > errors + 2)
    status = node.diagnostics('soft')
    print(f'soft: {status.message!r}; last_error '
          f'{diagnostic_values(node, "soft").get("last_error")!r}')
    assert status.level == DiagnosticStatus.ERROR and '\n' not in status.message
    assert node.values('soft', 'motor_current') == []  # nothing from before, as current
    assert node.values('soft', 'status_word') == []
    sim.reply_hook = None
    assert node.wait_state('soft', 'ready', 10.0)
    alive_and_serving(node, sim)


def test_a_drive_whose_every_bit_reads_set(node, hooked, conv_holds_10_pct):
    """Coils and registers of conv all read 1: a trip, every flag; no start goes out."""
    sim, conv = hooked, conv_holds_10_pct
    words = len(conv.control_words_received)
    sim.reply_hook = all_bits_set(1, functions=(0x01, 0x03))
    assert node.spin_until(lambda: node.state('conv') not in ('ready', ''), 5.0)
    assert node.wait_fresh_diagnostics()
    status = node.diagnostics('conv')
    print(f'conv: state {node.state("conv")}, {status.level!r} {status.message!r}')
    assert status.level in (DiagnosticStatus.WARN, DiagnosticStatus.ERROR)
    assert status.message and '\n' not in status.message
    received = list(conv.control_words_received)[words:]
    assert received and not any(word & 0x40 for word in received), \
        [hex(word) for word in received]  # never the start bit
    sim.reply_hook = None
    assert node.wait_state('conv', 'ready', 10.0)
    alive_and_serving(node, sim)


def test_the_node_ends_cleanly_and_never_wrote_to_the_monitor_only_drive(node, sim):
    """Last: SIGTERM the node; shutdown's stops too must leave the monitor-only drive alone."""
    code, output = stop_node(node.process)
    assert code == 0, output[-3000:]
    assert writes_to(sim, 2) == []
    assert 'Traceback' not in output


# -- parameters files the node is started with -----------------------------------------
HEAD = "/**/drive_bridge:\n  ros__parameters:\n    port: /dev/null\n    parity: 'N'\n"


@pytest.mark.parametrize('content, expected', [
    (HEAD + '    devices: [a]\n    devices: [b]\n', "key 'devices' is given twice"),
    (HEAD + '    devices: a\n    a: {family: mcd, address: 1}\n',
     "parameter 'devices' = 'a' has the wrong type"),
    (HEAD + '    devices: [a]\n    a: [1, 2]\n', "parameter 'a.family' is required"),
    (HEAD + '    devices: [a]\n    a: {family: mcd, address: 1, adress: 2}\n',
     "unknown parameter 'a.adress'"),
    (HEAD + '    devices: [a]\n    a: {family: mcd, address: 1, poll_rate: .nan}\n',
     'must be a finite number'),
    (HEAD + '    devices: [a, b]\n    a: {family: mcd, address: 1}\n'
     '    b: {family: mcd, address: 1}\n', 'addresses must be unique'),
    (b'# F\xf6rderband\n' + HEAD.encode(), 'the parameters file'),
    (bytes(range(256)), 'the parameters file'),
    (HEAD + '    devices: [a]\x00\n', 'is not valid YAML'),
    (HEAD + '    allow_runtime_control_enable: "false"\n    devices: [a]\n'
     '    a: {family: mcd, address: 1}\n',
     "parameter 'allow_runtime_control_enable' = 'false' has the wrong type"),
    (HEAD + '    autostart: "no"\n    devices: [a]\n    a: {family: mcd, address: 1}\n',
     "parameter 'autostart' = 'no' has the wrong type"),
], ids=['key twice', 'devices a string', 'device block a list', 'misspelt key', 'nan',
        'address twice', 'latin-1 comment', 'binary', 'NUL', 'quoted false', 'quoted no'])
def test_a_bad_parameters_file_stops_the_node_with_one_line(tmp_path, content, expected):
    path = tmp_path / 'params.yaml'
    if isinstance(content, bytes):
        path.write_bytes(content)
    else:
        path.write_text(content)
    process = start_node(str(path))
    process.wait(timeout=30.0)  # it stops by itself
    code, output = stop_node(process)
    print(output)
    assert code == 2, output
    assert 'Traceback' not in output, output
    assert len(output.strip().splitlines()) == 1 and expected in output, output
