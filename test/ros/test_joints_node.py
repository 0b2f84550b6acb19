"""
ros2_control through the node: two simulated FC 51s as the wheels of a two-wheel base.

The client behaves as ``joint_state_topic_hardware_interface/JointStateTopicSystem`` does
(its source, 1.1.0): it subscribes to the states with the sensor-data QoS (best effort,
depth 5) and keeps the latest message; at 100 Hz it publishes one JointState with every
joint's velocity command (reliable, depth 1) to ``~/joint_commands``. Motor state is read
from the simulated drives, never from the bridge.
"""

import math
import time

from diagnostic_msgs.msg import DiagnosticStatus
from drive_bridge.sim.devices import make_device, make_sim_server
import pytest
from rclpy.qos import qos_profile_sensor_data, QoSProfile, ReliabilityPolicy
from rclpy.serialization import serialize_message
from ros_helpers import node_output, running_node, serving
from sensor_msgs.msg import JointState

# One worker runs this module's tests: its node, a module fixture, then starts once, not
# once on every worker that takes one of them.
pytestmark = pytest.mark.xdist_group('joints_node')

SCALE = 20.0  # rad/s at 100 %: 10 rad/s = 50 % = 0x2000
WHEELS = ('left_wheel_joint', 'right_wheel_joint')
DEVICES = {
    'left': {'family': 'fc', 'model': 'fc51', 'address': 1, 'poll_rate': 20.0,
             'velocity_scale': SCALE, 'joint_name': 'left_wheel_joint'},
    # Mounted mirrored: the motor turns the other way than the joint.
    'right': {'family': 'fc', 'model': 'fc51', 'address': 2, 'poll_rate': 20.0,
              'velocity_scale': -SCALE, 'joint_name': 'right_wheel_joint'},
}
SIM_SETTINGS = {'fc': {'ramp_up_s': 1.0, 'ramp_down_s': 0.5, 'quick_stop_ramp_s': 0.3}}
COMMAND_PERIOD_S = 0.01


class JointClient:
    """JointStateTopicSystem's side of the topics, on the test client's rclpy node."""

    def __init__(self, client):
        self.client = client
        node = client.node
        self.states = []  # (receive time, message)
        self.latest = {}  # joint -> (stamp_s, position, velocity, receive time)
        node.create_subscription(JointState, '/drive_bridge/joint_states', self._on_state,
                                 qos_profile_sensor_data)
        self.publisher = node.create_publisher(
            JointState, '/drive_bridge/joint_commands',
            QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE))
        self.velocities = dict.fromkeys(WHEELS, 0.0)
        self.sending = True
        self.sent = 0
        node.create_timer(COMMAND_PERIOD_S, self._write)

    def _on_state(self, message):
        now = time.monotonic()
        self.states.append((now, message))
        stamp = message.header.stamp.sec + message.header.stamp.nanosec * 1e-9
        for index, name in enumerate(message.name):
            self.latest[name] = (stamp, message.position[index], message.velocity[index], now)

    def _write(self):
        if not self.sending:
            return
        message = JointState(name=list(self.velocities),
                             velocity=[float(v) for v in self.velocities.values()])
        message.header.stamp = self.client.node.get_clock().now().to_msg()
        self.publisher.publish(message)
        self.sent += 1

    def command(self, **velocities):
        """Set the velocity commands of the next messages (joint name=rad/s)."""
        self.velocities.update(velocities)

    def velocity(self, name):
        return self.latest[name][2] if name in self.latest else None

    def samples(self, name):
        """Return (stamp_s, position, velocity, receive time) of every state of ``name``."""
        result = []
        for received, message in self.states:
            for index, joint in enumerate(message.name):
                if joint == name:
                    stamp = message.header.stamp.sec + message.header.stamp.nanosec * 1e-9
                    result.append((stamp, message.position[index], message.velocity[index],
                                   received))
        return result

    def spin_until(self, predicate, timeout_s=10.0):
        return self.client.spin_until(predicate, timeout_s)

    def spin_for(self, seconds):
        self.client.spin_until(lambda: False, seconds)

    def near(self, name, velocity, tolerance=0.01):
        value = self.velocity(name)
        return value is not None and abs(value - velocity) <= tolerance


def values(client, device):
    status = client.diagnostics(device) or DiagnosticStatus()
    return {kv.key: kv.value for kv in status.values}


def commands_status(client):
    for array in reversed(client.messages['/diagnostics']):
        for status in array.status:
            if status.name == 'drive_bridge: ~/joint_commands':
                return status
    return None


def command_counters(client):
    status = commands_status(client)
    return {kv.key: kv.value for kv in status.values} if status else {}


@pytest.fixture(scope='module')
def sim():
    with serving(make_sim_server({1: 'fc51', 2: 'fc51'}, settings=SIM_SETTINGS)) as server:
        yield server


@pytest.fixture(scope='module')
def node(sim, tmp_path_factory):
    with running_node(tmp_path_factory.mktemp('params') / 'wheels.yaml',
                      {'port': sim.pty_path, 'parity': 'N', 'timeout': 1.0,
                       'backoff_max': 1.0, 'diagnostics_period': 0.2}, DEVICES,
                      drives=list(DEVICES), ready=list(DEVICES)) as client:
        yield client


@pytest.fixture(scope='module')
def joints(node):
    client = JointClient(node)
    assert client.spin_until(lambda: set(WHEELS) <= set(client.latest), 15.0), \
        'no joint states'
    return client


@pytest.fixture
def wheels(sim, node, joints):
    """Yield the two simulated drives; stop, reset and re-arm everything after each test."""
    drives = (sim.devices[1].model, sim.devices[2].model)
    joints.sending = True
    with sim.lock:  # each test sees the words written in its own time (tests share the drives)
        for drive in drives:
            drive.control_words_received.clear()
    yield drives
    joints.sending = True
    joints.command(left_wheel_joint=0.0, right_wheel_joint=0.0)
    for device in DEVICES:
        assert node.set_parameter(f'{device}.command_mode', 'reference').successful
        assert node.set_parameter(f'{device}.reference_timeout', 0.0).successful
        assert node.set_parameter(f'{device}.allow_control', True).successful
    with sim.lock:
        for drive in drives:
            drive.local_mode = False
            drive.parameters[341] = round(SIM_SETTINGS['fc']['ramp_up_s'] * 100)
    for unit, device in ((1, 'left'), (2, 'right')):
        drive = sim.devices[unit].model
        if drive.tripped or drive.output_pct or drive.control_word & 0x40:
            node.call(device, 'reset')
            node.call(device, 'coast_stop')
    for device in DEVICES:
        assert node.wait_state(device, 'ready')


def _start(node, device):
    """Start ``device``; once more if the reply was lost (a loaded machine delays the sim)."""
    response = node.call(device, 'start')
    if not response.success and 'no acknowledgement' in response.message:
        response = node.call(device, 'start')
    return response.success


def _set(node, name, value):
    result = node.set_parameter(name, value)
    assert result.successful, result.reason


def _auto_start_mode(node, joints, device, joint, delay_s=1.0):
    """Switch ``device`` to auto_start and arm it with a zero command, as a switch needs."""
    _set(node, f'{device}.command_mode', 'auto_start')
    _set(node, f'{device}.auto_stop_delay', delay_s)
    joints.command(**{joint: 0.0})
    assert node.wait_fresh_diagnostics()
    assert node.spin_until(lambda: values(node, device).get('auto_start') == 'armed')


def test_joint_states_carry_both_wheels_in_si_with_increasing_stamps(node, joints, wheels):
    assert joints.spin_until(lambda: all(joints.near(name, 0.0) for name in WHEELS))
    start = len(joints.states)
    joints.spin_for(1.0)
    for name in WHEELS:
        recent = joints.samples(name)[-10:]
        stamps = [sample[0] for sample in recent]
        assert stamps == sorted(stamps) and len(set(stamps)) == len(stamps)
        # Stamps are the node's ROS time (system clock): close to ours, a little earlier.
        now_ros = node.node.get_clock().now().nanoseconds * 1e-9
        assert -1.0 < now_ros - stamps[-1] < 2.0
    # One joint per message, published once per poll of that drive (20 Hz each).
    new = joints.states[start:]
    assert all(len(message.name) == 1 and len(message.position) == 1 and
               len(message.velocity) == 1 and not message.effort for _, message in new)
    assert 10 <= len(new) <= 50


def test_start_ramp_reverse_and_stop(node, joints, wheels, sim):
    left, right = wheels
    with sim.lock:
        left.parameters[341] = 400  # 3-41 ramp-up 4 s: several readings on the way up
    joints.command(left_wheel_joint=10.0, right_wheel_joint=10.0)
    joints.spin_for(0.1)
    ramp_from = time.monotonic()
    for device in DEVICES:
        assert _start(node, device)
    # The start carries the reference in force; right: -50 %, mounted mirrored.
    assert left.reference_word == 0x2000 and right.reference_word == 0xE000
    assert joints.spin_until(lambda: joints.near(WHEELS[0], 10.0) and
                             joints.near(WHEELS[1], 10.0))
    assert right.output_pct == -50.0 and left.output_pct == 50.0
    ramp = [sample[2] for sample in joints.samples(WHEELS[0]) if sample[3] > ramp_from]
    assert sum(0.5 < velocity < 9.5 for velocity in ramp) >= 2, ramp  # seen ramping up
    assert ramp == sorted(ramp)  # up the ramp, never down
    joints.command(left_wheel_joint=-10.0, right_wheel_joint=-4.0)
    assert joints.spin_until(lambda: joints.near(WHEELS[0], -10.0) and
                             joints.near(WHEELS[1], -4.0))
    assert left.output_pct == -50.0 and abs(right.output_pct - 20.0) < 0.01
    for device in DEVICES:
        assert node.call(device, 'stop').success
    assert left.control_word == 0x043C and right.control_word == 0x043C
    assert joints.spin_until(lambda: joints.near(WHEELS[0], 0.0) and
                             joints.near(WHEELS[1], 0.0))
    for device in DEVICES:
        assert node.wait_state(device, 'ready')


def test_position_integrates_within_one_percent_over_ten_seconds(node, joints, wheels):
    left, right = wheels
    joints.command(left_wheel_joint=10.0, right_wheel_joint=-6.0)
    for device in DEVICES:
        assert _start(node, device)
    assert joints.spin_until(lambda: joints.near(WHEELS[0], 10.0) and
                             joints.near(WHEELS[1], -6.0, 0.002))
    first = {name: joints.latest[name] for name in WHEELS}
    outputs = (left.output_pct, right.output_pct)
    assert joints.spin_until(lambda: all(joints.latest[name][0] - first[name][0] >= 10.0
                                         for name in WHEELS), 30.0)
    assert (left.output_pct, right.output_pct) == outputs  # constant speed all along
    for name, commanded in zip(WHEELS, (10.0, -6.0)):
        stamp0, position0, _, received0 = first[name]
        stamp1, position1, _, received1 = joints.latest[name]
        elapsed_s = stamp1 - stamp0
        # The simulated drive's own output integrated: constant, so speed x time.
        expected = commanded * elapsed_s
        assert abs((position1 - position0) - expected) <= 0.01 * abs(expected), \
            (name, position1 - position0, expected)
        # The stamps run with real time (receive times jitter with the load).
        assert abs(elapsed_s - (received1 - received0)) < 1.0
    positions = [sample[1] for sample in joints.samples(WHEELS[0])
                 if sample[3] >= first[WHEELS[0]][3]]
    assert len(positions) > 20 and positions == sorted(positions)  # forward: monotonic


def test_deadman_stops_the_wheels_when_commands_stop(node, joints, wheels):
    left, right = wheels
    _set(node, 'left.reference_timeout', 0.5)
    joints.command(left_wheel_joint=4.0)
    assert _start(node, 'left')
    joints.spin_for(1.5)  # 100 Hz commands keep it running
    assert left.control_word == 0x047C and left.reference_word == 0x0CCC
    assert joints.near(WHEELS[0], 4.0, 0.01)
    joints.sending = False
    assert node.wait_state('left', 'ready', 5.0)
    assert left.control_word == 0x043C
    assert joints.spin_until(lambda: joints.near(WHEELS[0], 0.0))
    assert node.spin_until(lambda: int(values(node, 'left').get('deadman_stops', 0)) >= 1)


def _counter(client, device, key):
    return int(values(client, device).get(key, '0'))


def test_auto_start_starts_on_nonzero_and_stops_after_a_held_zero(node, joints, wheels):
    left, _ = wheels
    _auto_start_mode(node, joints, 'left', WHEELS[0], 0.5)
    starts = _counter(node, 'left', 'auto_starts')
    joints.command(left_wheel_joint=6.0)
    assert joints.spin_until(lambda: left.control_word == 0x047C)  # no service called
    assert joints.spin_until(lambda: joints.near(WHEELS[0], 6.0, 0.002))
    assert node.wait_state('left', 'running')
    joints.spin_for(0.5)
    assert left.control_words_received.count(0x047C) >= 1
    joints.command(left_wheel_joint=0.0)
    zero_at = time.monotonic()
    assert joints.spin_until(lambda: left.control_word == 0x043C)
    assert time.monotonic() - zero_at >= 0.5  # held for auto_stop_delay first
    assert node.wait_state('left', 'ready')
    assert node.spin_until(lambda: _counter(node, 'left', 'auto_starts') == starts + 1 and
                           _counter(node, 'left', 'auto_stops') >= 1)
    # A zero shorter than auto_stop_delay does not stop it.
    _set(node, 'left.auto_stop_delay', 2.0)
    joints.command(left_wheel_joint=3.0)
    assert joints.spin_until(lambda: left.control_word == 0x047C)
    assert joints.spin_until(lambda: joints.near(WHEELS[0], 3.0, 0.002))
    stops = _counter(node, 'left', 'auto_stops')
    left.control_words_received.clear()
    joints.command(left_wheel_joint=0.0)
    joints.spin_for(0.2)
    joints.command(left_wheel_joint=3.0)
    joints.spin_for(0.5)
    assert joints.spin_until(lambda: joints.near(WHEELS[0], 3.0, 0.002))
    assert 0x043C not in left.control_words_received and left.control_word == 0x047C
    assert node.wait_fresh_diagnostics()
    assert _counter(node, 'left', 'auto_stops') == stops


def test_reference_mode_never_starts_a_drive(node, joints, wheels):
    left, right = wheels
    left.control_words_received.clear()
    right.control_words_received.clear()
    joints.command(left_wheel_joint=5.0, right_wheel_joint=5.0)
    joints.spin_for(1.0)
    assert left.output_pct == 0.0 and right.output_pct == 0.0
    # The keepalive rewrites the stop image in force (with the new reference), never a start.
    for drive in (left, right):
        assert 0x047C not in drive.control_words_received
    assert left.reference_word in (0, 0x1000) and right.reference_word in (0, 0xF000)
    assert node.state('left') == 'ready' and node.state('right') == 'ready'


def test_auto_start_is_not_retried_after_a_failure_nor_after_a_trip(node, joints, wheels, sim):
    left, _ = wheels
    _auto_start_mode(node, joints, 'left', WHEELS[0], 0.3)
    with sim.lock:
        left.local_mode = True  # the drive ignores the bus: the start is refused
    assert node.spin_until(lambda: 'local operation' in (
        node.diagnostics('left') or DiagnosticStatus()).message)
    assert node.wait_fresh_diagnostics()
    failures = _counter(node, 'left', 'auto_start_failures')
    joints.command(left_wheel_joint=5.0)
    assert node.spin_until(lambda: _counter(node, 'left', 'auto_start_failures') ==
                           failures + 1)
    with sim.lock:
        left.local_mode = False
    joints.spin_for(1.0)  # nonzero all along: not retried
    assert _counter(node, 'left', 'auto_start_failures') == failures + 1
    assert 0x047C not in left.control_words_received and left.output_pct == 0.0
    assert 'waits for a zero command' in values(node, 'left')['auto_start']
    joints.command(left_wheel_joint=0.0)  # zero and back re-arms it
    joints.spin_for(0.1)
    joints.command(left_wheel_joint=5.0)
    assert joints.spin_until(lambda: left.control_word == 0x047C)
    assert joints.spin_until(lambda: joints.near(WHEELS[0], 5.0, 0.002))
    # A trip: never reset automatically, no restart after a manual reset until zero and back.
    with sim.lock:
        left.trip(5, sim.clock())
    assert node.wait_state('left', 'tripped')
    joints.spin_for(1.0)
    assert left.tripped and joints.latest[WHEELS[0]][3] < time.monotonic() - 0.5
    assert node.call('left', 'reset').success
    assert node.wait_state('left', 'ready')
    joints.spin_for(1.0)  # still commanding 5 rad/s: no automatic start
    assert left.output_pct == 0.0 and left.control_word != 0x047C
    joints.command(left_wheel_joint=0.0)
    joints.spin_for(0.1)
    joints.command(left_wheel_joint=5.0)
    assert joints.spin_until(lambda: left.control_word == 0x047C)


def test_a_stop_service_is_not_undone_by_auto_start(node, joints, wheels):
    left, _ = wheels
    _auto_start_mode(node, joints, 'left', WHEELS[0])
    joints.command(left_wheel_joint=5.0)
    assert joints.spin_until(lambda: left.control_word == 0x047C)
    assert node.wait_state('left', 'running')
    assert node.call('left', 'stop').success
    assert node.wait_state('left', 'ready')
    joints.spin_for(1.0)
    assert left.control_word == 0x043C and left.output_pct == 0.0


def _publish_once(joints, names, velocities=None):
    message = JointState(name=list(names))
    if velocities is not None:
        message.velocity = [float(v) for v in velocities]
    joints.publisher.publish(message)


def _hold_a_good_command(node, joints, left, right):
    """Stop both drives, command 2 rad/s until both references are written, stop sending."""
    for device in DEVICES:  # a stop: the stop image is kept alive with the reference in force
        assert node.call(device, 'stop').success
    joints.command(left_wheel_joint=2.0, right_wheel_joint=2.0)
    assert joints.spin_until(
        lambda: left.reference_word == 0x0666 and right.reference_word == 0xF99A)
    joints.sending = False


def test_bad_commands_are_refused_and_nothing_is_sent(node, joints, wheels):
    left, right = wheels
    _hold_a_good_command(node, joints, left, right)
    joints.spin_for(0.2)
    assert node.wait_fresh_diagnostics()
    rejected = _counter(node, 'left', 'rejected_references')
    before = command_counters(node)
    bad = [math.nan, math.inf, -math.inf, 2 * SCALE, -2 * SCALE - 0.5, 1e308]
    for velocity in bad:
        _publish_once(joints, ['left_wheel_joint'], [velocity])
    _publish_once(joints, ['caster_joint', 'left_wheel_joint'], [1.0, math.nan])
    _publish_once(joints, ['left_wheel_joint'])  # no velocities
    _publish_once(joints, ['left_wheel_joint', 'right_wheel_joint'], [1.0])  # malformed
    assert node.spin_until(lambda: _counter(node, 'left', 'rejected_references') ==
                           rejected + len(bad) + 1)
    assert node.spin_until(lambda: int(command_counters(node).get('unknown_joint_names', 0))
                           == int(before['unknown_joint_names']) + 1)
    counters = command_counters(node)
    assert int(counters['messages_without_velocity']) == \
        int(before['messages_without_velocity']) + 1
    assert int(counters['messages_malformed']) == int(before['messages_malformed']) + 1
    assert commands_status(node).level == DiagnosticStatus.WARN
    joints.spin_for(0.3)
    assert left.reference_word == 0x0666 and right.reference_word == 0xF99A  # unchanged
    _publish_once(joints, ['left_wheel_joint'], [3.0])  # and a good one is taken
    assert joints.spin_until(lambda: left.reference_word == 0x0999)


def _malformed_commands():
    """Return serialized JointStates that are not whole (cut short, a huge length, ...)."""
    good = serialize_message(JointState(name=list(WHEELS), velocity=[5.0, 5.0]))
    name_at = good.index(WHEELS[0].encode())
    return {'cut in the velocities': good[:-12],
            'frame_id 4 GB long': good[:12] + b'\xff\xff\xff\xff' + good[16:],
            'a name that is not UTF-8': good[:name_at] + b'\xff' + good[name_at + 1:],
            'another encapsulation, garbage': b'\x00\x07\x00\x00' + b'\x5a' * 20}


def test_malformed_bytes_say_why_in_one_line_send_nothing_and_the_node_lives(
        node, joints, wheels):
    left, right = wheels
    _hold_a_good_command(node, joints, left, right)
    joints.spin_for(1.1)  # the log throttle's period: the first malformed message is logged
    assert node.wait_fresh_diagnostics()
    before = int(command_counters(node)['messages_malformed'])
    control = (left.control_word, right.control_word)
    malformed = _malformed_commands()
    for data in malformed.values():
        joints.publisher.publish(data)  # bytes: published as they are
    assert node.spin_until(lambda: int(command_counters(node).get('messages_malformed', 0))
                           == before + len(malformed))
    joints.spin_for(0.3)
    assert left.reference_word == 0x0666 and right.reference_word == 0xF99A  # unchanged
    assert (left.control_word, right.control_word) == control
    output = node_output(node.process)
    reasons = [line for line in output.splitlines() if 'not a JointState' in line]
    assert reasons and all('ignored, nothing sent' in line for line in reasons), output[-2000:]
    assert 'Traceback' not in output
    _publish_once(joints, ['left_wheel_joint'], [3.0])  # the node lives and takes a good one
    assert joints.spin_until(lambda: left.reference_word == 0x0999)


def test_a_monitor_only_joint_takes_no_command_and_nothing_is_written(node, joints, wheels):
    _, right = wheels
    _set(node, 'right.allow_control', False)
    assert node.wait_fresh_diagnostics()
    rejected = _counter(node, 'right', 'rejected_references')
    words = len(right.control_words_received)
    reference = right.reference_word
    joints.command(right_wheel_joint=7.0)
    window_from = time.monotonic()
    joints.spin_for(1.0)
    assert _counter(node, 'right', 'rejected_references') > rejected + 20
    assert len(right.control_words_received) == words and right.reference_word == reference
    assert joints.near(WHEELS[1], 0.0)  # its states are still published
    assert any(sample[3] > window_from for sample in joints.samples(WHEELS[1]))
    refused = node.set_parameter('right.command_mode', 'auto_start')
    assert not refused.successful and 'monitor-only' in refused.reason


def test_joint_commands_at_100_hz_cost_no_bus_traffic(node, joints, wheels, sim):
    left, right = wheels
    joints.command(left_wheel_joint=2.0, right_wheel_joint=2.0)
    for device in DEVICES:
        assert _start(node, device)
    assert joints.spin_until(lambda: joints.near(WHEELS[0], 2.0, 0.002))

    def window(sending):
        joints.sending = sending
        joints.spin_for(0.3)
        with sim.lock:
            sim.stats.frames.clear()
            sim.record_frames = True
            recording_from = time.monotonic()
        sent = joints.sent
        steps = 0
        while time.monotonic() - recording_from < 2.0:
            steps += 1
            joints.command(left_wheel_joint=2.0 + 0.01 * (steps % 50))  # keeps changing
            joints.spin_for(0.02)
        with sim.lock:
            sim.record_frames = False
            recorded_s = time.monotonic() - recording_from  # 2 s and the last step's overrun
            frames = list(sim.stats.frames)
        functions = [frame[1] for frame in frames]
        return functions, joints.sent - sent, recorded_s

    quiet = window(False)
    busy = window(True)
    assert busy[1] >= 100  # commands did flow at about 100 Hz (fewer under load)
    for functions, _, recorded_s in (quiet, busy):
        # Every poll is one keepalive write (0x0F) and one status read (0x01): no write of
        # its own for a reference.
        assert abs(functions.count(0x0F) - functions.count(0x01)) <= 2
        # Two drives at 20 Hz at most, over the time the simulator recorded: for each drive
        # the polls due in it (due times are a period apart at least: schedule_next in
        # bus/device.py), at most 20 x recorded_s + 1, and at most two due before it (one
        # whose status read falls in it, and one that a stalled machine made late). A
        # command that polled would add about 100 a second.
        assert functions.count(0x01) <= 2 * (20 * recorded_s + 3), recorded_s
    quiet, busy = quiet[0], busy[0]
    # The same transactions a poll either way (4: write, status, current, one readout).
    per_poll_quiet = len(quiet) / quiet.count(0x01)
    per_poll_busy = len(busy) / busy.count(0x01)
    assert abs(per_poll_busy - per_poll_quiet) < 0.3


def test_an_offline_drive_is_left_out_then_comes_back(node, joints, wheels, sim):
    sim.power_off(2)
    try:
        assert node.wait_state('right', 'offline', 15.0)
        joints.spin_for(0.2)
        count_right = len(joints.samples(WHEELS[1]))
        count_left = len(joints.samples(WHEELS[0]))
        joints.spin_for(2.0)
        assert len(joints.samples(WHEELS[1])) == count_right  # nothing stale
        assert len(joints.samples(WHEELS[0])) > count_left  # the other joint goes on
    finally:
        sim.power_on(2, make_device('fc51', **SIM_SETTINGS['fc']))
    assert node.wait_state('right', 'ready', 15.0)
    assert joints.spin_until(lambda: len(joints.samples(WHEELS[1])) > count_right)
