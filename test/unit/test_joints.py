"""
Unit tests of the ros2_control joints: settings, integration, auto_start, the bridge.

The bridge runs on a real bus over a fake FC 51 with a fake clock; its JointState messages
are collected instead of published.
"""

import math

from drive_bridge.bus.events import ReadingEvent
from drive_bridge.bus.master import BusMaster, BusTiming
from drive_bridge.config import model as config
from drive_bridge.devices.contracts import DeviceReading
from drive_bridge.errors import ConfigError, NoResponse
from drive_bridge.protocol import words
from drive_bridge.protocol.commands import Command
from drive_bridge.protocol.requests import ReadCoils, ReadRegisters, WriteCoils
from drive_bridge.transport.base import Transport
from drive_bridge.transport.link import LinkSettings
from fakes import FakeClock, kind, run_for
import pytest

# rclpy is not in the pymodbus 3.6.9 venv (transport tiers only): skipped there.
joints = pytest.importorskip('drive_bridge.ros.node.joints', reason='ROS 2 (rclpy) from PyPI')
JointState = pytest.importorskip('sensor_msgs.msg').JointState

DRIVE = {'family': 'fc', 'model': 'fc51', 'address': 1}
READY = 0x0607  # status word: control ready, unit ready, enabled, bus control


def build(**devices):
    return config.build_config({'devices': list(devices)}, devices)


# -- settings ------------------------------------------------------------------------------
def test_a_drive_is_a_joint_only_with_a_velocity_scale():
    built = build(conv={**DRIVE}, wheel={**DRIVE, 'address': 2, 'velocity_scale': 14.87})
    specs = joints.joint_specs(built.devices)
    assert [(s.device, s.name, s.velocity_scale, s.command_mode, s.auto_stop_delay_s)
            for s in specs] == [('wheel', 'wheel', 14.87, 'reference', 1.0)]


def test_joint_settings_are_refused_for_starters():
    with pytest.raises(ConfigError, match=r"'main.velocity_scale' applies to families fc, vlt"):
        build(main={'family': 'mcd', 'model': 'mcd500', 'address': 20, 'velocity_scale': 1.0})


@pytest.mark.parametrize('settings, message', [
    ({'velocity_scale': 20000.0}, r"'w.velocity_scale' = 20000.0 is out of range: allowed "
                                  r'\[-10000, 10000\]'),
    ({'velocity_scale': math.nan}, r"'w.velocity_scale' = nan must be a finite number"),
    ({'velocity_scale': 1.0, 'command_mode': 'auto'},
     r"'w.command_mode' = 'auto' is invalid: allowed reference, auto_start"),
    ({'velocity_scale': 1.0, 'auto_stop_delay': -1.0}, r"'w.auto_stop_delay' = -1.0 is out"),
    ({'velocity_scale': 1.0, 'joint_name': 'left wheel'},
     r"'w.joint_name' = 'left wheel' is invalid: use a letter or _"),
    ({'joint_name': 'left'}, r"'w.joint_name' = 'left' applies to joints only: set "
                             r'w.velocity_scale'),
    ({'command_mode': 'auto_start'}, r"'w.command_mode' = 'auto_start' applies to joints"),
    ({'velocity_scale': 1.0, 'command_mode': 'auto_start', 'allow_control': False},
     r"'w.command_mode' = 'auto_start' is refused: a monitor-only drive"),
])
def test_bad_joint_settings_get_one_line(settings, message):
    with pytest.raises(ConfigError, match=message) as error:
        build(w={**DRIVE, **settings})
    assert '\n' not in str(error.value)


def test_joint_names_are_unique_across_the_node():
    with pytest.raises(ConfigError, match=r"'b.joint_name': joint name 'a' is also the joint "
                                          r"of 'a': joint names must be unique"):
        build(a={**DRIVE, 'velocity_scale': 1.0},
              b={**DRIVE, 'address': 2, 'velocity_scale': 1.0, 'joint_name': 'a'})
    # A drive that is not a joint does not take a joint name.
    build(a={**DRIVE}, b={**DRIVE, 'address': 2, 'velocity_scale': 1.0, 'joint_name': 'a'})


def test_joint_settings_in_the_parameter_tables():
    settings = {setting.name: setting for setting in config.REFERENCE_SETTINGS}
    assert not settings['velocity_scale'].runtime and not settings['joint_name'].runtime
    assert settings['command_mode'].runtime and settings['auto_stop_delay'].runtime
    assert settings['command_mode'].choices == ('reference', 'auto_start')


# -- integration ---------------------------------------------------------------------------
def test_position_is_the_trapezoid_sum_exact_for_ramps():
    integrator = joints.Integrator()
    assert integrator.add(10.0, 0.0) == 0.0  # the first sample adds nothing
    for step in range(1, 11):  # a ramp 0 -> 10 rad/s in 1 s, then 1 s constant
        integrator.add(10.0 + 0.1 * step, 10.0 * step / 10)
    assert integrator.position_rad == pytest.approx(5.0)
    integrator.add(12.0, 10.0)
    assert integrator.position_rad == pytest.approx(15.0)
    integrator.add(11.5, 99.0)  # an older stamp adds no area
    assert integrator.position_rad == pytest.approx(15.0)


def test_an_outage_holds_the_position_and_starts_afresh():
    integrator = joints.Integrator()
    integrator.add(0.0, 2.0)
    integrator.add(1.0, 2.0)
    integrator.interrupt()
    integrator.add(5.0, 4.0)  # nothing is guessed for the outage
    assert integrator.position_rad == pytest.approx(2.0)
    integrator.add(6.0, 4.0)
    assert integrator.position_rad == pytest.approx(6.0)


# -- auto_start decisions ------------------------------------------------------------------
STOPPED = joints.DriveFacts(holds_run=False, online=True, tripped=False, allow_control=True)
RUNNING = joints.DriveFacts(holds_run=True, online=True, tripped=False, allow_control=True)


def test_nonzero_starts_once_zero_held_stops_once():
    auto = joints.AutoStart(delay_s=0.5)
    assert auto.command(True, 0.0, STOPPED) is Command.START
    assert auto.command(True, 0.01, STOPPED) is None  # in flight: never two
    auto.start_done(None)
    assert auto.command(True, 0.02, RUNNING) is None
    assert auto.command(False, 1.0, RUNNING) is None  # zero since 1.0
    assert auto.reading(1.49, RUNNING) is None
    assert auto.reading(1.5, RUNNING) is Command.STOP
    assert auto.command(False, 1.6, RUNNING) is None  # in flight: never two
    auto.stop_done(None)
    assert auto.reading(1.7, STOPPED) is None
    assert not auto.blocked  # our own stop does not block the next start
    assert auto.command(True, 2.0, STOPPED) is Command.START
    assert (auto.starts, auto.stops, auto.failed_starts) == (2, 1, 0)


def test_a_short_zero_does_not_stop():
    auto = joints.AutoStart(delay_s=0.5)
    auto.holding = True
    assert auto.command(False, 0.0, RUNNING) is None
    assert auto.command(True, 0.4, RUNNING) is None
    assert auto.command(False, 0.45, RUNNING) is None
    assert auto.reading(0.9, RUNNING) is None  # 0.45 s of the new zero
    assert auto.reading(0.96, RUNNING) is Command.STOP


def test_a_failed_start_is_not_retried_until_zero_and_back():
    auto = joints.AutoStart(delay_s=0.5)
    assert auto.command(True, 0.0, STOPPED) is Command.START
    auto.start_done(RuntimeError('rejected by left: local operation'))
    assert 'automatic start failed (rejected by left: local operation)' in auto.blocked
    assert auto.command(True, 0.1, STOPPED) is None
    assert auto.command(True, 5.0, STOPPED) is None
    assert auto.command(False, 5.1, STOPPED) is None
    assert auto.command(True, 5.2, STOPPED) is Command.START
    assert auto.failed_starts == 1 and auto.starts == 2


@pytest.mark.parametrize('facts', [
    joints.DriveFacts(holds_run=False, online=True, tripped=True, allow_control=True),
    joints.DriveFacts(holds_run=False, online=False, tripped=False, allow_control=True),
    joints.DriveFacts(holds_run=False, online=True, tripped=False, allow_control=False),
    RUNNING])
def test_no_start_for_a_tripped_offline_monitor_only_or_running_drive(facts):
    assert joints.AutoStart(0.5).command(True, 0.0, facts) is None


def test_a_trip_or_a_stop_from_elsewhere_blocks_until_zero_and_back():
    tripped = joints.DriveFacts(holds_run=False, online=True, tripped=True, allow_control=True)
    for after_run in (tripped, STOPPED):  # a trip; a stop service or the deadman
        auto = joints.AutoStart(delay_s=0.5)
        assert auto.command(True, 0.0, STOPPED) is Command.START
        auto.start_done(None)
        assert auto.reading(0.1, RUNNING) is None
        assert auto.reading(0.2, after_run) is None
        assert auto.blocked and auto.log
        assert auto.command(True, 0.3, STOPPED) is None  # a reset drive is not restarted
        auto.command(False, 0.4, STOPPED)
        assert auto.command(True, 0.5, STOPPED) is Command.START


MONITOR_ONLY = joints.DriveFacts(holds_run=False, online=True, tripped=False,
                                 allow_control=False)


def test_a_command_already_there_when_control_returns_starts_nothing():
    # Found by an adversarial probe through the node: armed by a zero, then allow_control
    # false at runtime, the controller's nonzero command refused meanwhile; when control came
    # back the next nonzero command started the motor (19 ms after). Seen monitor-only (a
    # reading) or a refused command: automatic starts wait for zero and back.
    for seen in ('reading', 'refused'):
        auto = joints.AutoStart(delay_s=0.5)
        assert auto.command(False, 0.0, STOPPED) is None  # armed
        if seen == 'reading':
            assert auto.reading(0.1, MONITOR_ONLY) is None
        else:
            auto.refused('motor is monitor only (allow_control is false)')
        assert auto.blocked and auto.log
        assert auto.command(True, 0.2, STOPPED) is None  # control is back: still nothing
        assert auto.command(True, 5.0, STOPPED) is None
        assert auto.command(False, 5.1, STOPPED) is None
        assert auto.command(True, 5.2, STOPPED) is Command.START


def test_a_zero_while_monitor_only_does_not_arm_a_start_before_control_returns():
    auto = joints.AutoStart(delay_s=0.5)
    assert auto.command(False, 0.0, MONITOR_ONLY) is None
    assert auto.command(True, 0.1, MONITOR_ONLY) is None  # refused by the facts, blocked
    assert auto.blocked
    assert auto.command(True, 0.2, STOPPED) is None  # the nonzero was there before
    assert auto.command(False, 0.3, STOPPED) is None
    assert auto.command(True, 0.4, STOPPED) is Command.START


def test_zeros_while_tripped_do_not_arm_and_log_once():
    # A zero used to arm automatic starts again and the next observation of the trip to
    # block them: two warnings a message at the stream's rate until the trip was reset.
    tripped = joints.DriveFacts(holds_run=False, online=True, tripped=True, allow_control=True)
    auto = joints.AutoStart(delay_s=0.5)
    for index in range(100):
        assert auto.command(False, index * 0.01, tripped) is None
    assert auto.blocked and len(auto.log) == 1, auto.log
    assert auto.command(True, 1.1, STOPPED) is None  # reset: the nonzero was not a new one
    assert auto.command(False, 1.2, STOPPED) is None
    assert auto.command(True, 1.3, STOPPED) is Command.START


def test_a_failed_automatic_stop_is_sent_again_only_with_the_next_decision():
    auto = joints.AutoStart(delay_s=0.0)
    auto.holding = True
    assert auto.command(False, 0.0, RUNNING) is Command.STOP
    auto.stop_done(RuntimeError('no acknowledgement'))
    assert not auto.blocked  # still running: the next reading stops it
    assert auto.reading(0.1, RUNNING) is Command.STOP


# -- the bridge on a bus -------------------------------------------------------------------
class FakeFc51(Transport):
    """FC 51s on a fake line: a status word and an actual value per address, writes kept."""

    def __init__(self, clock):
        super().__init__(LinkSettings())
        self.clock = clock
        self._connected = False
        self.status = {}
        self.actual = {}
        self.silent = set()
        self.writes = []

    @property
    def connected(self):
        return self._connected

    def connect(self):
        self._connected = True

    def close(self):
        self._connected = False

    def execute(self, unit, request):
        self.clock.now += 0.005
        if unit in self.silent:
            raise NoResponse('no reply')
        if isinstance(request, ReadCoils):
            return list(words.words_to_coils([self.status.get(unit, READY),
                                              self.actual.get(unit, 0)]))
        if isinstance(request, ReadRegisters):
            return [0] * request.count
        if isinstance(request, WriteCoils):
            self.writes.append((unit, words.coils_to_words(list(request.values))))
        return None


class Logger:
    def __init__(self):
        self.lines = []

    def info(self, text):
        self.lines.append(('info', text))

    def warning(self, text):
        self.lines.append(('warning', text))

    def error(self, text):
        self.lines.append(('error', text))


class Bench:
    """A bus with two wheel drives, the bridge, and what it published."""

    def __init__(self, **left):
        self.clock = FakeClock()
        self.line = FakeFc51(self.clock)
        built = build(left={**DRIVE, 'poll_rate': 10.0, 'velocity_scale': 20.0,
                            'joint_name': 'left_wheel', **left},
                      right={**DRIVE, 'address': 2, 'poll_rate': 10.0,
                             'velocity_scale': -20.0, 'joint_name': 'right_wheel'})
        self.events = []
        self.bus = BusMaster(self.line, [d.make_spec() for d in built.devices],
                             BusTiming(retries=0, offline_after=2, backoff_initial_s=1.0,
                                       backoff_max_s=1.0),
                             listener=self._on_event, clock=self.clock, sleep=self.clock.sleep)
        self.sent = []
        self.active = True
        self.logger = Logger()
        self.bridge = joints.JointBridge(self.bus, joints.joint_specs(built.devices),
                                         self.sent.append, self.logger, lambda: self.active,
                                         stamp_offset_ns=1_000_000_000_000, clock=self.clock)

    def _on_event(self, event):
        self.events.append(event)
        self.bridge.on_bus_event(event)

    def run(self, seconds):
        run_for(self.bus, self.clock, seconds)

    def command(self, **velocities):
        self.bridge.on_commands(JointState(name=list(velocities),
                                           velocity=[float(v) for v in velocities.values()]))

    def reference_word(self, device):
        return self.bus._devices[device].owner.reference_word

    def stats(self, device):
        return self.bus.snapshot(device).stats

    def states(self, joint):
        return [(m.header.stamp.sec * 10**9 + m.header.stamp.nanosec, m.position[0],
                 m.velocity[0]) for m in self.sent if m.name == [joint]]


def test_every_reading_is_one_joint_state_in_si_stamped_on_the_node_clock():
    bench = Bench()
    bench.line.actual[1] = 0x2000  # 50 %
    bench.line.actual[2] = 0x2000  # 50 %, mirrored: -10 rad/s
    bench.run(1.0)
    left = bench.states('left_wheel')
    right = bench.states('right_wheel')
    assert 9 <= len(left) <= 11 and 9 <= len(right) <= 11
    assert {velocity for _, _, velocity in left} == {10.0}
    assert {velocity for _, _, velocity in right} == {-10.0}
    readings = [e for e in bench.events if kind(e) == 'reading' and e.device == 'left']
    assert [stamp for stamp, _, _ in left] == \
        [1_000_000_000_000 + round(e.stamp_s * 1e9) for e in readings]
    first, last = left[0], left[-1]
    assert last[1] - first[1] == pytest.approx(10.0 * (last[0] - first[0]) * 1e-9)
    assert all(not m.effort and len(m.position) == 1 for m in bench.sent)


def test_tripped_offline_and_unread_drives_are_left_out():
    bench = Bench()
    bench.line.silent.add(2)
    bench.line.actual[1] = 0x1000
    bench.run(0.5)
    assert bench.states('right_wheel') == []  # never read
    count = len(bench.states('left_wheel'))
    bench.line.status[1] = READY | 1 << 3  # tripped: the output is off
    bench.line.actual[1] = 0
    bench.run(0.5)
    assert len(bench.states('left_wheel')) <= count + 1
    bench.line.status[1] = READY
    bench.line.silent.add(1)
    bench.run(1.0)
    assert bench.bus.snapshot('left').online is False
    position = bench.bridge.joints['left'].integrator.position_rad
    count = len(bench.states('left_wheel'))
    bench.line.silent.discard(1)
    bench.line.actual[1] = 0x1000  # back at 5 rad/s: nothing is guessed for the outage
    bench.run(3.0)
    after = bench.states('left_wheel')[count:]
    assert after and after[0][1] == pytest.approx(position) and after[0][2] == 5.0


def test_commands_become_speed_references_by_the_scale():
    bench = Bench()
    bench.run(0.3)
    bench.command(left_wheel=10.0, right_wheel=4.0)
    assert bench.reference_word('left') == 0x2000
    assert bench.reference_word('right') == (-3276) & 0xFFFF  # -20 %: mirrored
    writes = len(bench.line.writes)
    for _ in range(100):  # a burst of commands writes nothing by itself
        bench.command(left_wheel=5.0)
    assert len(bench.line.writes) == writes


def test_bad_commands_are_counted_and_nothing_is_taken():
    bench = Bench()
    bench.run(0.3)
    bench.command(left_wheel=2.0)
    for bad in (math.nan, math.inf, 40.0, -40.5, 1e308):
        bench.command(left_wheel=bad)
    assert bench.reference_word('left') == 0x0666
    assert bench.stats('left')['rejected_references'] == '5'
    bench.command(caster=1.0, left_wheel=3.0)
    assert bench.reference_word('left') == 0x0999  # known names in the message are taken
    bench.bridge.on_commands(JointState(name=['left_wheel']))
    bench.bridge.on_commands(JointState(name=['left_wheel', 'right_wheel'], velocity=[1.0]))
    assert bench.reference_word('left') == 0x0999
    assert bench.bridge.counters == {'messages': 9, 'unknown_names': 1,
                                     'without_velocity': 1, 'malformed': 1}
    status = bench.bridge.commands_status('drive_bridge: ~/joint_commands')
    values = {kv.key: kv.value for kv in status.values}
    assert values['unknown_joint_names'] == '1' and values['messages_malformed'] == '1'
    warnings = [text for level, text in bench.logger.lines if level == 'warning']
    assert any("unknown joint 'caster'" in text for text in warnings)


def test_serialized_commands_are_taken_as_the_messages_they_carry():
    serialize = pytest.importorskip('rclpy.serialization').serialize_message
    bench = Bench()
    bench.run(0.3)
    bench.bridge.on_serialized_commands(serialize(JointState(
        name=['left_wheel', 'right_wheel'], velocity=[10.0, 4.0], position=[1.0, 2.0])))
    assert bench.reference_word('left') == 0x2000
    assert bench.reference_word('right') == (-3276) & 0xFFFF
    data = serialize(JointState(name=['left_wheel'], velocity=[2.0]))
    bench.bridge.on_serialized_commands(data[:-6])  # cut short: nothing taken
    bench.bridge.on_serialized_commands(b'\x00\x01\x00')
    assert bench.reference_word('left') == 0x2000
    assert bench.bridge.counters == {'messages': 3, 'unknown_names': 0,
                                     'without_velocity': 0, 'malformed': 2}
    status = bench.bridge.commands_status('drive_bridge: ~/joint_commands')
    assert 'not a JointState' in status.message and 'nothing sent' in status.message


@pytest.mark.parametrize('names, velocities', [
    (['left_wheel', 'left_wheel'], [3.0, math.nan]),
    (['left_wheel', 'left_wheel'], [3.0, 2.5]),
    (['left_wheel', 'left_wheel'], [3.0, 3.0]),  # the same twice: still a repeated name
    (['right_wheel', 'left_wheel', 'left_wheel'], [1.0, 3.0, 2.5]),  # the others neither
    (['caster', 'left_wheel', 'caster'], [1.0, 3.0, 2.0]),  # an unknown name twice
], ids=['then NaN', 'then 2.5', 'same value', 'with another joint', 'unknown twice'])
def test_a_message_naming_a_joint_twice_is_refused_whole(names, velocities):
    serialize = pytest.importorskip('rclpy.serialization').serialize_message
    bench = Bench(command_mode='auto_start')
    bench.run(0.3)
    writes = len(bench.line.writes)
    stats = {device: bench.stats(device) for device in ('left', 'right')}
    repeated = next(name for name in names if names.count(name) > 1)
    bench.bridge.on_commands(JointState(name=names, velocity=velocities))
    bench.bridge.on_serialized_commands(serialize(JointState(name=names, velocity=velocities)))
    assert (bench.reference_word('left'), bench.reference_word('right')) == (0, 0)
    assert bench.line.writes[writes:] == []  # nothing sent, nothing started
    assert {device: bench.stats(device) for device in ('left', 'right')} == stats
    assert bench.bridge.counters == {'messages': 2, 'unknown_names': 0,
                                     'without_velocity': 0, 'malformed': 2}
    warnings = [text for level, text in bench.logger.lines if level == 'warning']
    assert len(warnings) == 1 and '\n' not in warnings[0]  # throttled: once a second
    assert f'joint {repeated!r} named 2 times in one message' in warnings[0]
    assert 'nothing sent' in warnings[0]
    status = bench.bridge.commands_status('drive_bridge: ~/joint_commands')
    values = {kv.key: kv.value for kv in status.values}
    assert values['messages_malformed'] == '2' and values['last_ignored'] == warnings[0]
    bench.run(0.5)
    assert not bench.bus.snapshot('left').holds_run and not bench.bus.snapshot('right').holds_run
    bench.command(left_wheel=2.0, right_wheel=-4.0)  # a message that names each once is taken
    assert (bench.reference_word('left'), bench.reference_word('right')) == (0x0666, 0x0CCC)


def test_repeated_names_are_logged_apart_from_other_malformed_messages():
    bench = Bench()
    bench.run(0.3)
    bench.bridge.on_commands(JointState(name=['left_wheel', 'right_wheel'], velocity=[1.0]))
    bench.bridge.on_commands(JointState(name=['left_wheel', 'left_wheel'], velocity=[1.0, 2.0]))
    warnings = [text for level, text in bench.logger.lines if level == 'warning']
    assert len(warnings) == 2 and 'velocities: ignored' in warnings[0]
    assert "joint 'left_wheel' named 2 times" in warnings[1]


def test_a_joint_named_thousands_of_times_gets_one_short_line():
    serialize = pytest.importorskip('rclpy.serialization').serialize_message
    bench = Bench()
    bench.run(0.3)
    count = 20000
    bench.bridge.on_serialized_commands(serialize(JointState(
        name=[f'j{index}' for index in range(count)] + ['left_wheel'] * count,
        velocity=[1.0] * (2 * count))))
    assert bench.reference_word('left') == 0
    assert bench.bridge.counters['malformed'] == 1
    (line,) = [text for level, text in bench.logger.lines if level == 'warning']
    assert f"joint 'left_wheel' named {count} times" in line
    assert '[1.0, 1.0, 1.0, 1.0, ...]' in line and len(line) < 300


def test_warnings_are_logged_at_most_once_a_second_per_kind():
    bench = Bench()
    bench.run(0.3)
    for _ in range(50):
        bench.command(caster=1.0)
        bench.clock.now += 0.01
    bench.clock.now += 1.0
    bench.command(caster=1.0)
    lines = [text for _, text in bench.logger.lines if 'caster' in text]
    assert len(lines) == 2 and '(49 more like it in the last 1 s)' in lines[1]


def test_inactive_node_takes_no_command():
    bench = Bench()
    bench.run(0.3)
    bench.active = False
    bench.command(left_wheel=10.0)
    assert bench.reference_word('left') == 0
    assert 'not active' in bench.logger.lines[-1][1]


def test_monitor_only_joint_refuses_commands_and_writes_nothing():
    bench = Bench(allow_control=False)
    bench.run(0.3)
    bench.command(left_wheel=10.0)
    bench.run(0.5)
    assert bench.reference_word('left') == 0 and bench.stats('left')['rejected_references'] \
        == '1'
    assert [unit for unit, _ in bench.line.writes if unit == 1] == []


def test_auto_start_on_a_bus():
    bench = Bench(command_mode='auto_start', auto_stop_delay=0.5)
    bench.run(0.3)
    bench.command(left_wheel=5.0)
    bench.run(0.3)
    assert bench.bus.snapshot('left').holds_run
    starts = [w for unit, w in bench.line.writes if unit == 1 and w[0] == 0x047C]
    assert starts and starts[0][1] == 0x1000  # the start carries the new reference
    bench.command(left_wheel=0.0)
    bench.run(0.3)
    assert bench.bus.snapshot('left').holds_run  # not yet
    bench.run(0.5)  # readings carry the held zero on: no further command needed
    assert not bench.bus.snapshot('left').holds_run
    assert bench.line.writes[-1] == (1, [0x043C, 0])
    values = {kv.key: kv.value for kv in bench.bridge.device_values('left')}
    assert (values['auto_starts'], values['auto_stops'], values['auto_start']) == \
        ('1', '1', 'armed')
    logged = [text for _, text in bench.logger.lines]
    assert any('automatic start (nonzero joint command)' in text for text in logged)
    assert any('automatic ramp stop (zero joint command held 0.5 s)' in text for text in logged)


def test_an_auto_start_command_that_came_while_inactive_starts_nothing_once_active():
    bench = Bench(command_mode='auto_start', auto_stop_delay=0.5)
    bench.run(0.3)
    bench.active = False
    bench.command(left_wheel=5.0)  # refused: the node is not active
    bench.run(0.3)
    bench.active = True
    bench.command(left_wheel=5.0)  # already there before the activation
    bench.run(0.3)
    assert not bench.bus.snapshot('left').holds_run
    assert not [w for unit, w in bench.line.writes if unit == 1 and w[0] == 0x047C]
    bench.command(left_wheel=0.0)
    bench.command(left_wheel=5.0)  # zero and back: a new request
    bench.run(0.3)
    assert bench.bus.snapshot('left').holds_run


def test_runtime_command_mode_changes():
    bench = Bench()
    bench.run(0.3)
    bench.bridge.check_settings({'left': {'command_mode': 'auto_start'}})
    with pytest.raises(ConfigError, match='monitor-only'):
        bench.bridge.check_settings({'left': {'command_mode': 'auto_start',
                                              'allow_control': False}})
    bench.command(left_wheel=5.0)
    bench.bridge.apply_settings({'left': {'command_mode': 'auto_start',
                                          'auto_stop_delay': 0.2}})
    bench.command(left_wheel=5.0)
    bench.run(0.3)
    assert not bench.bus.snapshot('left').holds_run  # a switch never starts by itself
    assert 'wait for a zero command first' in bench.logger.lines[-1][1]
    bench.command(left_wheel=0.0)
    bench.command(left_wheel=5.0)
    bench.run(0.3)
    assert bench.bus.snapshot('left').holds_run
    bench.bridge.apply_settings({'left': {'command_mode': 'reference'}})
    bench.command(left_wheel=0.0)
    bench.run(1.0)
    assert bench.bus.snapshot('left').holds_run  # reference mode: zero is just a reference


def test_stamp_offset_moves_the_bus_clock_onto_the_node_clock():
    class Clock:
        def now(self):
            return type('Now', (), {'nanoseconds': 5_000_000_000})()

    node = type('Node', (), {'get_clock': lambda self: Clock()})()
    assert joints.stamp_offset_ns(node, lambda: 2.0) == 3_000_000_000


def test_reading_without_speed_feedback_is_left_out():
    bench = Bench()
    bench.bridge.on_bus_event(ReadingEvent(device='left', stamp_s=1.0,
                                           reading=DeviceReading('ready', READY)))
    assert bench.sent == []
