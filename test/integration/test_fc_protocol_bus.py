"""The bus over the Danfoss FC protocol: drives on a pty against the FC-protocol simulator."""

from drive_bridge.bus.master import BusMaster
from drive_bridge.config.model import build_config
from drive_bridge.devices.contracts import ParameterOptions
from drive_bridge.errors import CommandRefused
from drive_bridge.protocol.fc_profile import RAMP_STOP_WORD, START_WORD
from drive_bridge.sim.fc_protocol_server import make_fc_protocol_server
from integration_helpers import wait_until
import pytest
from safety_helpers import FaultOnStart

DEVICES = {
    'conv': {'family': 'fc', 'model': 'fc51', 'address': 1, 'poll_rate': 20.0,
             'speed_reference': 40.0, 'comms_timeout': 5.5, 'comms_timeout_function': 2},
    'fan': {'family': 'vlt', 'model': 'vlt5000', 'address': 2, 'poll_rate': 20.0,
            'speed_reference': 50.0},
    'watch': {'family': 'vlt', 'model': 'vlt6000', 'address': 3, 'allow_control': False},
}


@pytest.fixture
def line():
    server = make_fc_protocol_server({1: 'fc51', 2: 'vlt5000', 3: 'vlt6000'},
                                     {'ramp_up_s': 0.2, 'ramp_down_s': 0.2})
    server.open_pty()
    server.start()
    config = build_config({'protocol': 'fc_protocol', 'port': server.pty_path, 'parity': 'N',
                           'timeout': 0.3, 'devices': list(DEVICES)}, DEVICES)
    bus = BusMaster(config.make_transport(), [d.make_spec() for d in config.devices],
                    config.timing).start()
    assert wait_until(lambda: all(bus.snapshot(name).reading for name in DEVICES), 5.0)
    yield server, bus
    bus.shutdown(stop_motors=False)
    server.stop()


def state(bus, name):
    reading = bus.snapshot(name).reading
    return reading.state if reading else None


def received(server, unit):
    """Return the control words the simulated drive received, in order."""
    return [word for word, _ in server.devices[unit].process_received]


def test_start_reference_stop_and_readouts_in_one_telegram_a_poll(line):
    server, bus = line
    drive = server.devices[1].model
    assert wait_until(lambda: drive.parameters[803] == 55 and drive.parameters[804] == 2, 3.0)
    assert bus.snapshot('conv').model == 'fc51'
    assert all(not word & 1 << 10 for word in received(server, 1))  # nothing valid yet
    assert bus.submit_command('conv', 'start').result(3)
    assert wait_until(lambda: state(bus, 'conv') == 'running', 3.0)
    assert drive.control_word == START_WORD and drive.reference_word == 0x1999
    assert wait_until(lambda: (bus.snapshot('conv').reading.motor_current_a or 0) > 0.5, 3.0)
    bus.set_speed_reference('conv', -40.0)
    assert wait_until(lambda: bus.snapshot('conv').reading.speed_feedback_pct < -39.9, 3.0)
    assert bus.submit_command('conv', 'stop').result(3)
    assert wait_until(lambda: drive.output_pct == 0.0, 3.0)
    assert drive.control_word == RAMP_STOP_WORD
    stats = bus.snapshot('conv').stats
    assert int(stats['transactions']) > 10 and stats['errors'] == '0'


def test_vlt5000_current_trip_reset_and_parameters(line):
    server, bus = line
    drive = server.devices[2].model
    assert bus.submit_command('fan', 'start').result(3)
    assert wait_until(lambda: (bus.snapshot('fan').reading.motor_current_a or 0) > 0.1, 3.0)
    with server.lock:
        drive.trip(5, server.clock())
    assert wait_until(lambda: state(bus, 'fan') == 'tripped', 3.0)
    assert wait_until(lambda: drive.control_word == RAMP_STOP_WORD, 3.0)  # the run is ended
    with pytest.raises(CommandRefused, match='reset it first'):
        bus.submit_command('fan', 'start').result(1)
    assert bus.submit_command('fan', 'reset').result(3)
    assert wait_until(lambda: state(bus, 'fan') == 'ready', 3.0)
    assert drive.output_pct == 0.0
    assert bus.write_parameter('fan', 104, 60, ParameterOptions(eeprom=True)).result(3)
    assert bus.read_parameter('fan', 104).result(3) == 60
    with pytest.raises(CommandRefused, match='FC protocol error'):
        bus.write_parameter('fan', 520, 1.0).result(3)  # a readout: no write access


def test_monitor_only_drive_is_read_and_never_written(line):
    server, bus = line
    assert wait_until(lambda: len(received(server, 3)) > 10, 3.0)
    reading = bus.snapshot('watch').reading
    assert reading.state == 'ready' and reading.motor_current_a is not None
    with pytest.raises(CommandRefused, match='monitor only'):
        bus.submit_command('watch', 'start').result(1)
    assert all(word == 0 for word in received(server, 3))  # bit 10 clear: ignored
    assert server.devices[3].model.control_word == 0


def test_faults_are_counted_and_never_repeat_a_command(line):
    server, bus = line
    drive = server.devices[1].model
    # On the start's own reply: a fault injected for the unit's next reply went to a poll's
    # when a poll came first (seen with seven workers), and the start then succeeded.
    lost = FaultOnStart(server, 1, 'no_reply')
    future = bus.submit_command('conv', 'start')
    with pytest.raises(Exception, match='not repeated'):
        future.result(3)
    assert lost.fired.is_set()
    # the start may have run: the cyclic telegram now carries a stop, never the start again
    assert wait_until(lambda: drive.control_word == RAMP_STOP_WORD, 3.0)
    words = received(server, 1)
    assert words.count(START_WORD) == 1
    for fault, counted in (('bcc', 'crc'), ('truncated', 'truncated'),
                           ('wrong_address', 'wrong_address'), ('garbage', 'bad_frame')):
        server.faults.inject(1, fault)
        assert wait_until(lambda: bus.snapshot('conv').stats[f'errors_{counted}'] == '1', 5.0)
    assert wait_until(lambda: bus.snapshot('conv').online, 5.0)
