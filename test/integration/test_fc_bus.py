"""pymodbus (pinned and 3.6.9) and the bus against the simulated FC 51: coils, registers, text."""

from drive_bridge.bus.master import BusMaster, BusTiming
from drive_bridge.config.model import build_config
from drive_bridge.devices import fc51
from drive_bridge.devices.contracts import ParameterOptions
from drive_bridge.errors import CommandRefused, DeviceException
from drive_bridge.protocol import words
from drive_bridge.protocol.requests import (
    ReadCoils, ReadRegisters, WriteCoil, WriteCoils, WriteRegister, WriteRegisters)
from drive_bridge.sim.devices import make_sim_server
from drive_bridge.transport.engines import make_transport
from drive_bridge.transport.link import LinkSettings
from integration_helpers import wait_until
import pytest

FAST = {'fc': {'ramp_up_s': 0.5, 'ramp_down_s': 0.5}}


@pytest.fixture
def sim():
    server = make_sim_server({1: 'fc51', 20: 'mcd500'}, settings=FAST)
    server.open_pty()
    server.start()
    yield server
    server.stop()


@pytest.fixture
def transport(sim):
    # 2 s: no test here times a reply, and a busy machine can hold the simulator up (the
    # virtual machine itself stalled for over 1 s once beside a CPU hog)
    transport = make_transport(LinkSettings(port=sim.pty_path, parity='N', timeout_s=2.0))
    transport.connect()
    yield transport
    transport.close()


def test_process_data_as_coils(transport, sim):
    start = WriteCoils(0, words.words_to_coils([0x047C, 0x1999]))
    assert transport.execute(1, start) is None
    assert sim.devices[1].model.control_word == 0x047C
    assert sim.devices[1].model.reference_word == 0x1999
    coils = transport.execute(1, ReadCoils(32, 32))
    status_word, actual_word = words.coils_to_words(coils)
    assert status_word & (1 << 11) and status_word & (1 << 9)  # running, bus control


def test_registers_text_and_eeprom_coil(transport, sim):
    registers = transport.execute(1, ReadRegisters(fc51.DATA.spec(1540).address, 10, exact=False))
    assert words.registers_to_text(registers) == 'FC-051PK75T4E20H3BXC'
    version = transport.execute(1, ReadRegisters(fc51.DATA.spec(1543).address, 10, exact=False))
    assert version == words.text_to_registers('2.70', 4)  # a short text: a truncated reply
    assert transport.execute(1, WriteCoil(64, True)) is None
    assert sim.devices[1].model.eeprom_writes is True
    assert transport.execute(1, WriteRegisters(0x1CAB, (0, 0xFFFF))) is None  # PNU 734
    assert sim.devices[1].model.parameters[734] == 65535
    assert transport.execute(1, WriteRegister(0x1D, 1)) is None  # PNU 3
    assert transport.execute(1, ReadRegisters(0x0D5B, 2)) == [0, 50]  # 3-42: 0.50 s (FAST)


def test_exception_04_then_register_7(transport):
    with pytest.raises(DeviceException) as error:
        transport.execute(1, WriteRegister(fc51.DATA.spec(1614).address, 5))
    assert error.value.code == 4
    assert transport.execute(1, ReadRegisters(6, 1)) == [1]  # no write access


@pytest.mark.parametrize('parity', ['E', 'O'])
def test_fc_over_socket_url_with_parity(parity):
    server = make_sim_server({1: 'fc51'})
    port = server.open_tcp(framing='rtu')
    server.start()
    try:
        transport = make_transport(LinkSettings(port=f'socket://127.0.0.1:{port}',
                                                parity=parity, timeout_s=0.3))
        transport.connect()
        assert transport.execute(1, WriteCoils(0, words.words_to_coils([0x043C, 0]))) is None
        assert len(transport.execute(1, ReadCoils(32, 32))) == 32
        transport.close()
    finally:
        server.stop()


@pytest.fixture
def bus(sim):
    config = build_config(
        {'port': sim.pty_path, 'parity': 'N', 'timeout': 0.2, 'devices': ['conv', 'main']},
        {'conv': {'family': 'fc', 'address': 1, 'poll_rate': 20.0, 'speed_reference': 40.0,
                  'comms_timeout': 6.7, 'comms_timeout_function': 2},
         'main': {'family': 'mcd', 'address': 20, 'poll_rate': 10.0}})
    master = BusMaster(config.make_transport(), [d.make_spec() for d in config.devices],
                       BusTiming(backoff_max_s=2.0, frame_gap_s=config.timing.frame_gap_s))
    master.start()
    assert wait_until(lambda: master.snapshot('conv').online, 3.0)
    yield master
    master.shutdown(stop_motors=False)


def state(bus):
    reading = bus.snapshot('conv').reading
    return reading.state if reading else None


def test_drive_and_starter_on_one_bus(bus, sim):
    drive = sim.devices[1].model
    assert wait_until(lambda: drive.parameters[803] == 67 and drive.parameters[804] == 2, 2.0)
    assert bus.snapshot('conv').model == 'fc51'
    assert list(drive.control_words_received) == []  # nothing written before a command
    assert bus.submit_command('conv', 'start').result(3) == \
        'start acknowledged by conv (address 1)'
    assert wait_until(lambda: state(bus) == 'running', 3.0)
    assert drive.reference_word == 0x1999
    feedback = bus.snapshot('conv').reading.speed_feedback_pct
    assert feedback == pytest.approx(40.0, abs=0.01)
    bus.set_speed_reference('conv', -40.0)
    assert wait_until(lambda: bus.snapshot('conv').reading.speed_feedback_pct < -39.9, 3.0)
    assert drive.reference_word == 0xE667
    assert bus.snapshot('conv').reading.motor_current_a > 0.5
    assert bus.submit_command('main', 'start').result(3)
    assert bus.submit_command('conv', 'coast_stop').result(3)
    assert wait_until(lambda: state(bus) == 'ready', 2.0)
    assert drive.output_pct == 0.0


def test_alarm_trip_reset_and_parameters(bus, sim):
    drive = sim.devices[1].model
    with sim.lock:
        drive.trip(5, sim.clock())
    assert wait_until(lambda: state(bus) == 'tripped', 2.0)
    reading = bus.snapshot('conv').reading
    assert (reading.trip_code, reading.trip_name) == (13, 'Over current')
    with pytest.raises(CommandRefused, match='reset it first'):
        bus.submit_command('conv', 'start').result(1)
    assert bus.submit_command('conv', 'reset').result(3)
    assert wait_until(lambda: state(bus) == 'ready', 2.0)
    assert drive.control_word == 0x043C and drive.output_pct == 0.0  # no restart
    assert bus.read_parameter('conv', 1540).result(3) == 'FC-051PK75T4E20H3BXC'
    assert bus.write_parameter('conv', 341, 2.5, ParameterOptions(eeprom=True)).result(3)
    assert drive.parameters[341] == 250 and drive.eeprom_writes
    with pytest.raises(CommandRefused, match='no write access'):
        bus.write_parameter('conv', 1614, 1.0).result(3)
