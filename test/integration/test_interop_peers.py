"""
Interoperability with Modbus implementations no one here wrote: libmodbus and mbpoll.

The bridge's native engine against libmodbus's RTU slave (C, through ctypes:
``test/libmodbus_peer.py``), its mapping laid out as an MCD 500 behind its Modbus Module and
as an FC 51; and mbpoll, a libmodbus master, against the simulators (``test/mbpoll_peer.py``).
The expected frames and words are the manuals' (000: MCD Modbus Module; 004: FC 51; 003: the
VLT option card's frame of the same FC-profile coils), written out here, not taken from the
bridge's tables. libmodbus checked the CRC of every frame the bridge sent, and a frame it
refused fails the test.
"""

from typing import Dict, List, Sequence

from drive_bridge.bus.master import BusMaster
from drive_bridge.config.model import build_config
from drive_bridge.errors import CommandRefused, DeviceException
from drive_bridge.protocol.requests import ReadRegisters, WriteRegister
from drive_bridge.sim.devices import make_sim_server
from drive_bridge.transport.engines import make_transport
from drive_bridge.transport.link import LinkSettings
from integration_helpers import wait_until
from libmodbus_peer import LibmodbusSlave
from mbpoll_peer import run_mbpoll
import pytest

# The tests check what crosses the line, not how fast: a reply may wait on a busy machine.
SLACK_TIMEOUT_S = 2.0
WAIT_S = 10.0
MCD_UNIT = 20  # manual 000 section 8.1's examples: starter address 20
FC_UNIT = 1  # manual 004 section 5.5's examples: slave address 01


def rtu_frame(*data: int) -> bytes:
    """Return ``data`` with its CRC (Modbus over serial line: CRC-16 0xA001, low byte first)."""
    crc = 0xFFFF
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
    return bytes(data) + crc.to_bytes(2, 'little')


def word_of(coils: Sequence[bool]) -> int:
    """Return the word of 16 coils, the first coil its bit 0 (manual 004, 5.5.1's example)."""
    return sum(1 << index for index, on in enumerate(coils) if on)


def coils_of(word: int) -> List[bool]:
    """Return the 16 coils of ``word``, bit 0 first."""
    return [bool(word >> index & 1) for index in range(16)]


def text_registers(text: str, registers: int) -> List[int]:
    """Return ``text`` space-filled, two characters a register, the first in the high byte."""
    raw = text.encode('latin-1').ljust(2 * registers, b' ')
    return [raw[index] << 8 | raw[index + 1] for index in range(0, len(raw), 2)]


# -- the bridge's bus, as the node builds it ------------------------------------------------
def start_bus(port: str, device: Dict[str, object]) -> BusMaster:
    """Start a bus with one device ``dut`` on ``port``, the native engine, as the node does."""
    config = build_config(
        {'port': port, 'parity': 'N', 'timeout': SLACK_TIMEOUT_S, 'serial_engine': 'native',
         'command_deadline': 5.0, 'backoff_max': 2.0, 'devices': ['dut']},
        {'dut': device})
    master = BusMaster(config.make_transport(), [d.make_spec() for d in config.devices],
                       config.timing)
    return master.start()


def first_reading(bus: BusMaster):
    """Return the device's first reading (wait for it)."""
    assert wait_until(lambda: bus.snapshot('dut').reading is not None, WAIT_S), \
        bus.snapshot('dut').poll_failure
    return bus.snapshot('dut').reading


def written(peer: LibmodbusSlave, function: int) -> List[bytes]:
    """Return the requests of ``function`` libmodbus accepted; fail on any it refused."""
    assert peer.errors == []
    return [request for request in peer.requests_seen() if request[1] == function]


# -- the MCD 500 map, on libmodbus ------------------------------------------------------------
# Manual 000 section 6: 40002 command; 40003 status (bits 0-3 state: 1 ready, 3 running;
# bit 6 initialised); 40004 trip code (255 no trip); 40005 current (A); 40006 temperature;
# 40007 product (bits 3-7: 7 = MCD 500; bits 0-2 list version); 40008 protocol version;
# parameter N at 40008 + N. Frame address = register number - 40001.
MCD_READY, MCD_RUNNING = 0x41, 0x43  # state 1 or 3, bit 6 initialised
MCD_STATUS_BLOCK = [MCD_READY, 255, 0, 0, 7 << 3 | 1, 1]  # 40003-40008
MCD_PARAMETERS = 16  # 40009-40024 in the mapping: parameter 1 (Motor FLC) to 16


@pytest.fixture
def mcd_peer():
    """Yield libmodbus serving an MCD 500's registers 40002-40024 at unit 20."""
    with LibmodbusSlave(MCD_UNIT, registers=(1, 7 + MCD_PARAMETERS)) as peer:
        peer.set_registers(2, MCD_STATUS_BLOCK)
        peer.set_registers(8, [100])  # manual 000 section 8.1: par. 1-1 Motor FLC = 100 A
        yield peer


@pytest.fixture
def mcd_bus(mcd_peer):
    bus = start_bus(mcd_peer.path, {'family': 'mcd', 'address': MCD_UNIT, 'poll_rate': 10.0})
    yield bus
    bus.shutdown(stop_motors=False)


def test_mcd_poll_decodes_libmodbus_registers(mcd_peer):
    mcd_peer.set_registers(2, [MCD_RUNNING, 255, 123, 45])  # running, no trip, 123 A, 45 %
    bus = start_bus(mcd_peer.path, {'family': 'mcd', 'address': MCD_UNIT, 'poll_rate': 10.0})
    try:
        reading = first_reading(bus)
        assert bus.snapshot('dut').model == 'mcd500'  # model auto: from 40007
    finally:
        bus.shutdown(stop_motors=False)
    assert (reading.state, reading.trip_code) == ('running', 0)
    assert reading.motor_current_a == 123.0 and reading.motor_temperature_pct == 45.0
    # The first poll reads 40003-40008 in one request (section 8: reads start at 40003).
    assert written(mcd_peer, 0x03)[0] == rtu_frame(MCD_UNIT, 0x03, 0x00, 0x02, 0x00, 0x06)


def test_mcd_start_writes_register_40002(mcd_bus, mcd_peer):
    assert first_reading(mcd_bus).state == 'ready'
    assert 'start acknowledged' in mcd_bus.submit_command('dut', 'start').result(WAIT_S)
    assert mcd_peer.registers(1) == [1]  # 40002 = 1: Start
    # Manual 000 section 8.1, "Command: Start": 20, 06, 40002, 1.
    assert written(mcd_peer, 0x06) == [rtu_frame(MCD_UNIT, 0x06, 0x00, 0x01, 0x00, 0x01)]


def test_mcd_parameter_read_and_write(mcd_bus, mcd_peer):
    first_reading(mcd_bus)
    # Manual 000 section 8.1: "Read Parameter 1, Motor FLC, 100 A" (register 40009) and
    # "Write Parameter 4, Current Limit, set = 400% FLC" (register 40012 = 400).
    assert mcd_bus.read_parameter('dut', 1).result(WAIT_S) == 100
    assert rtu_frame(MCD_UNIT, 0x03, 0x00, 0x08, 0x00, 0x01) in written(mcd_peer, 0x03)
    assert mcd_bus.write_parameter('dut', 4, 400).result(WAIT_S)
    assert mcd_peer.registers(11) == [400]
    assert written(mcd_peer, 0x06) == [rtu_frame(MCD_UNIT, 0x06, 0x00, 0x0B, 0x01, 0x90)]
    # Parameter 100 (40108) is outside libmodbus's mapping: its exception 02.
    with pytest.raises(CommandRefused, match='Modbus error 02'):
        mcd_bus.read_parameter('dut', 100).result(WAIT_S)


# -- the FC 51 map, on libmodbus --------------------------------------------------------------
# Manual 004 section 5.2.8: coils 1-16 control word (CTW), 17-32 reference (REF), 33-48 status
# word (STW), 49-64 main actual value (MAV), 65 EEPROM; registers 50000 CTW, 50010 REF,
# 50200 STW, 50210 MAV (frame address = number - 1); PNU at 10 * PNU - 1 (section 5.4.1).
FC_REGISTERS = 50210  # frame addresses 0-50209: the parameters and the process data
FC_TYPE = 'FC-051PK75T4E20H3BXC'  # par. 15-40, 20 characters
# STW bits (5.2.8, coils 33-48): 0 control ready, 1 unit ready, 2 not coasted, 8 on
# reference, 9 auto mode (bus control), 10 in frequency range, 11 running.
FC_READY = 0x0607  # the STW of section 5.5.1's example
FC_RUNNING = FC_READY | 1 << 8 | 1 << 11
START_CTW = 0x047C  # coils 3-7 and 11 (no DC brake, no coast, no quick stop, no freeze,
# start, data valid): the FC profile's start
MAV_50_PCT = 0x2000  # 0x4000 = 100 % (section 7: "16384 (4000 Hex) corresponds to 100%")


def lay_out_fc51(peer: LibmodbusSlave, status_word: int, actual_word: int) -> None:
    """Set the peer's mapping as an FC 51 shows it: process data, identity, 16-14 = 2.50 A."""
    peer.set_coils(32, coils_of(status_word) + coils_of(actual_word))
    peer.set_registers(50199, [status_word])
    peer.set_registers(50209, [actual_word])
    peer.set_registers(15399, text_registers(FC_TYPE, 10))  # 15-40 FC Type
    peer.set_registers(15429, text_registers('2.70', 10))  # 15-43 Software Version
    peer.set_registers(16139, [0, 250])  # 16-14 Motor Current, int32, x0.01 A


@pytest.fixture
def fc_peer():
    """Yield libmodbus serving an FC 51's coils 1-65 and registers 0-50209 at unit 1."""
    with LibmodbusSlave(FC_UNIT, coils=(0, 65), registers=(0, FC_REGISTERS)) as peer:
        yield peer


def start_fc_bus(peer: LibmodbusSlave) -> BusMaster:
    return start_bus(peer.path, {'family': 'fc', 'address': FC_UNIT, 'poll_rate': 10.0,
                                 'speed_reference': 40.0})


def test_fc51_poll_decodes_libmodbus_coils_and_registers(fc_peer):
    lay_out_fc51(fc_peer, FC_RUNNING, MAV_50_PCT)
    bus = start_fc_bus(fc_peer)
    try:
        reading = first_reading(bus)
        assert bus.snapshot('dut').model == 'fc51'  # model auto: from 15-40
    finally:
        bus.shutdown(stop_motors=False)
    assert reading.state == 'running' and reading.status_word == FC_RUNNING
    assert reading.speed_feedback_pct == 50.0 and reading.motor_current_a == 2.5
    # Coils 33-64 in one read (section 5.5.1 reads 33-48 from address 0x20), 16-14 at 16139.
    assert rtu_frame(FC_UNIT, 0x01, 0x00, 0x20, 0x00, 0x20) in written(fc_peer, 0x01)
    assert rtu_frame(FC_UNIT, 0x03, 0x3F, 0x0B, 0x00, 0x02) in written(fc_peer, 0x03)
    assert written(fc_peer, 0x0F) == []  # no command in force: nothing written


def test_fc51_start_writes_the_control_word_and_reference_coils(fc_peer):
    lay_out_fc51(fc_peer, FC_READY, 0)
    bus = start_fc_bus(fc_peer)
    try:
        assert first_reading(bus).state == 'ready'
        assert 'start acknowledged' in bus.submit_command('dut', 'start').result(WAIT_S)
        control, reference = fc_peer.coils(0, 16), fc_peer.coils(16, 16)
    finally:
        bus.shutdown(stop_motors=False)
    # The coil table of section 5.2.8: coil 7 start, 3-6 "no" DC brake, coast, quick stop,
    # freeze, 11 data valid; preset reference, jog, ramp 2, relay, set-up 2, reversing off.
    assert [number for number, on in enumerate(control, 1) if on] == [3, 4, 5, 6, 7, 11]
    assert word_of(control) == START_CTW
    assert word_of(reference) == 0x1999  # "40% of 4000HEX = 1999HEX" (manual 003)
    # Manual 003 (the VLT option card: the same FC-profile coils), "Example 1: Start Motor,
    # Run Speed 40%", CRC included: one 0F request of coils 1-32, each word low byte first.
    start = bytes.fromhex('01 0F 00 00 00 20 04 7C 04 99 19 37 43')
    assert start == rtu_frame(FC_UNIT, 0x0F, 0, 0, 0, 0x20, 4, 0x7C, 0x04, 0x99, 0x19)
    assert set(written(fc_peer, 0x0F)) == {start}  # the command, and the keepalives after it


def test_fc51_parameter_and_process_registers(fc_peer):
    lay_out_fc51(fc_peer, FC_READY, 0)
    fc_peer.set_registers(3419, [0x0000, 0x0003])  # section 5.5.4's reply: PNU 342 = 3
    bus = start_fc_bus(fc_peer)
    try:
        first_reading(bus)
        # 3-42 Ramp 1 Ramp-down Time, conversion index -2: 3 is 0.03 s.
        assert bus.read_parameter('dut', 342).result(WAIT_S) == pytest.approx(0.03)
        assert bus.write_parameter('dut', 3, 1).result(WAIT_S)
    finally:
        bus.shutdown(stop_motors=False)
    # Section 5.5.4: read PNU 342 at 0x0D5B, 2 registers; 5.5.5: write 1 to PNU 3 at 0x001D.
    assert rtu_frame(FC_UNIT, 0x03, 0x0D, 0x5B, 0x00, 0x02) in written(fc_peer, 0x03)
    assert written(fc_peer, 0x06) == [rtu_frame(FC_UNIT, 0x06, 0x00, 0x1D, 0x00, 0x01)]
    assert fc_peer.registers(29) == [1]
    # Before it coil 65 off (RAM only; section 5.5.2 forces it at 0x40, FF00 = on).
    assert written(fc_peer, 0x05) == [rtu_frame(FC_UNIT, 0x05, 0x00, 0x40, 0x00, 0x00)]
    assert fc_peer.coils(64) == [False]


def test_fc51_process_data_registers_through_the_transport(fc_peer):
    lay_out_fc51(fc_peer, FC_RUNNING, MAV_50_PCT)
    transport = make_transport(LinkSettings(protocol='modbus_rtu', port=fc_peer.path,
                                            baudrate=9600, parity='N',
                                            timeout_s=SLACK_TIMEOUT_S))
    transport.connect()
    try:
        status = transport.execute(FC_UNIT, ReadRegisters(50199, 1))  # register 50200 STW
        actual = transport.execute(FC_UNIT, ReadRegisters(50209, 1))  # register 50210 MAV
        assert transport.execute(FC_UNIT, WriteRegister(50009, 0x1999)) is None  # 50010 REF
        assert transport.execute(FC_UNIT, WriteRegister(49999, START_CTW)) is None  # 50000
        with pytest.raises(DeviceException) as refused:  # past libmodbus's mapping
            transport.execute(FC_UNIT, ReadRegisters(FC_REGISTERS, 1))
    finally:
        transport.close()
    assert (status, actual) == ([FC_RUNNING], [MAV_50_PCT])
    assert fc_peer.registers(49999) == [START_CTW] and fc_peer.registers(50009) == [0x1999]
    assert refused.value.code == 2
    # Addresses above 0x7FFF, high byte first: 50199 = 0xC417, 49999 = 0xC34F.
    assert written(fc_peer, 0x03) == [rtu_frame(FC_UNIT, 0x03, 0xC4, 0x17, 0x00, 0x01),
                                      rtu_frame(FC_UNIT, 0x03, 0xC4, 0x21, 0x00, 0x01),
                                      rtu_frame(FC_UNIT, 0x03, 0xC4, 0x22, 0x00, 0x01)]
    assert written(fc_peer, 0x06) == [rtu_frame(FC_UNIT, 0x06, 0xC3, 0x59, 0x19, 0x99),
                                      rtu_frame(FC_UNIT, 0x06, 0xC3, 0x4F, 0x04, 0x7C)]


# -- mbpoll (libmodbus as the master) against the simulators -------------------------------
@pytest.fixture
def sim():
    """Yield the simulated MCD 500 (20) and FC 51 (1) on one pty, requests recorded."""
    server = make_sim_server({MCD_UNIT: 'mcd500', FC_UNIT: 'fc51'},
                             settings={'mcd': {'start_time_s': 0.5},
                                       'fc': {'ramp_up_s': 0.5, 'ramp_down_s': 0.5}})
    server.record_frames = True
    server.open_pty()
    server.start()
    yield server
    server.stop()


def requests_of(sim) -> List[bytes]:
    """Return the requests the simulator received since the last call (and forget them)."""
    with sim.lock:
        frames = list(sim.stats.frames)
        sim.stats.frames.clear()
    return frames


def advanced(sim, model):
    """Return ``model`` advanced to now (a simulated device moves on when it is asked)."""
    with sim.lock:
        model.advance(sim.clock())
    return model


def test_mbpoll_reads_the_mcd_status_registers(sim):
    model = sim.devices[MCD_UNIT].model
    # mbpoll counts references from 1: reference 3 is register 40003, frame address 2.
    one_based = run_mbpoll(sim.pty_path, MCD_UNIT, 3, ['-c', '6'])
    assert one_based.status == 0, one_based.stderr
    assert requests_of(sim) == [rtu_frame(MCD_UNIT, 0x03, 0x00, 0x02, 0x00, 0x06)]
    # -0: references are frame addresses; the same request, the same words.
    zero_based = run_mbpoll(sim.pty_path, MCD_UNIT, 2, ['-0', '-c', '6', '-t', '4:hex'])
    assert zero_based.status == 0, zero_based.stderr
    assert requests_of(sim) == [rtu_frame(MCD_UNIT, 0x03, 0x00, 0x02, 0x00, 0x06)]
    words = [one_based.values()[reference] for reference in range(3, 9)]
    assert words == [zero_based.values()[address] for address in range(2, 8)]
    # Ready and initialised, no trip, no current, MCD 500 list 1, protocol 1 (section 6).
    assert words == MCD_STATUS_BLOCK
    assert words[:2] == [model.status_word(), model.trip_code]
    assert model.motor_current_a == 0.0 and model.features.product_type == 7


def test_mbpoll_read_of_40002_gets_exception_03(sim):
    # Section 9: 03 "not readable data" (40002 is write-only); libmodbus's name for 03.
    result = run_mbpoll(sim.pty_path, MCD_UNIT, 2, verbose=True)
    assert result.status != 0 and result.failure() == 'Illegal data value'
    assert result.received() == rtu_frame(MCD_UNIT, 0x83, 0x03)


def test_mbpoll_starts_the_simulated_mcd(sim):
    model = sim.devices[MCD_UNIT].model
    result = run_mbpoll(sim.pty_path, MCD_UNIT, 2, values=[1])  # 40002 = 1: Start
    assert result.status == 0 and 'Written 1 references' in result.stdout, result.stderr
    # Manual 000 section 8.1, "Command: Start", echoed by the module.
    assert requests_of(sim) == [rtu_frame(MCD_UNIT, 0x06, 0x00, 0x01, 0x00, 0x01)]
    assert list(model.commands_received) == [1] and model.state == 2  # starting
    assert wait_until(lambda: advanced(sim, model).state == 3, WAIT_S)  # running


@pytest.mark.parametrize('reference, value, code, libmodbus_name', [
    (3, 5, 0x04, 'Slave device or server failure'),  # 40003 is read-only: not writable
    (2, 6, 0x06, 'Slave device or server is busy'),  # 40002 takes 1-5: invalid command
])
def test_mbpoll_refused_write_gets_the_modules_exception(sim, reference, value, code,
                                                         libmodbus_name):
    model = sim.devices[MCD_UNIT].model
    result = run_mbpoll(sim.pty_path, MCD_UNIT, reference, values=[value], verbose=True)
    # Manual 000 section 9: its own codes; libmodbus names them as the Modbus spec does.
    assert result.status != 0 and result.failure() == libmodbus_name
    assert result.received() == rtu_frame(MCD_UNIT, 0x86, code)
    assert requests_of(sim) == [rtu_frame(MCD_UNIT, 0x06, 0x00, reference - 1, 0x00, value)]
    assert model.state == 1 and list(model.commands_received) == []  # nothing done


def read_fc_process_word(sim, reference: int) -> int:
    """Return the word mbpoll reads at ``reference`` (50200 STW, 50210 MAV) of the FC 51."""
    result = run_mbpoll(sim.pty_path, FC_UNIT, reference, ['-t', '4:hex'])
    assert result.status == 0, result.stderr
    return result.values()[reference]


def test_mbpoll_reads_the_fc51_status_word_and_actual_value(sim):
    drive = sim.devices[FC_UNIT].model
    assert read_fc_process_word(sim, 50200) == drive.status_word()
    assert read_fc_process_word(sim, 50210) == drive.actual_word() == 0
    assert requests_of(sim) == [rtu_frame(FC_UNIT, 0x03, 0xC4, 0x17, 0x00, 0x01),
                                rtu_frame(FC_UNIT, 0x03, 0xC4, 0x21, 0x00, 0x01)]
    # CTW first: the simulator drops a reference while the control word in force has bit
    # 10 "data not valid" (section 5.6.1: the control word is ignored).
    for reference, word in ((50000, START_CTW), (50010, MAV_50_PCT)):
        result = run_mbpoll(sim.pty_path, FC_UNIT, reference, values=[word])
        assert result.status == 0, result.stderr
    assert (drive.control_word, drive.reference_word) == (START_CTW, MAV_50_PCT)
    assert wait_until(lambda: advanced(sim, drive).output_pct == 50.0, WAIT_S)
    status_word = read_fc_process_word(sim, 50200)
    assert status_word == drive.status_word()
    assert status_word & FC_RUNNING == FC_RUNNING  # running, on reference, bus control
    assert read_fc_process_word(sim, 50210) == drive.actual_word() == MAV_50_PCT
    assert requests_of(sim)[:2] == [rtu_frame(FC_UNIT, 0x06, 0xC3, 0x4F, 0x04, 0x7C),
                                    rtu_frame(FC_UNIT, 0x06, 0xC3, 0x59, 0x20, 0x00)]
