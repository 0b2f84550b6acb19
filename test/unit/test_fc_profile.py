"""Unit tests of the FC control profile, the FC 51 drive profile and the FC 51 model."""

import math

from drive_bridge.devices import fc51
from drive_bridge.devices.contracts import (
    FixedControl, ParameterOptions, SlowReadouts, TRIP_CODE_UNKNOWN)
from drive_bridge.devices.fc_profile_drive import FcProfileModbusDrive
from drive_bridge.devices.parameters import decode_value, encode_value, FC_CONVERSION_FACTORS
from drive_bridge.errors import CommandRefused, DeviceException, ModelMismatch
from drive_bridge.protocol import crc, fc_profile, rtu, words
from drive_bridge.protocol.commands import Command
from drive_bridge.protocol.fc_profile import StatusWord
from drive_bridge.protocol.requests import (
    ReadCoils, ReadRegisters, WriteCoil, WriteCoils, WriteRegister, WriteRegisters)
from drive_bridge.sim.fc_profile_modbus_device import FcProfileModbusDevice
from drive_bridge.sim.fc_profile_model import FcProfileModel, FcProfileSimConfig
from drive_bridge.sim.fc_profile_parameter_store import ParameterError
from fakes import drive_cycle
import pytest


def frame(text):
    return bytes.fromhex(text)


# -- manual 004 chapter 5 and the VLT option card manual: frames as vectors -----------
def test_start_at_40_percent_is_the_manuals_0f_frame():
    profile = FcProfileModbusDrive(fc51.DATA, 'fc51')
    control = FixedControl(reference_word=profile.reference_word(40.0))
    write = profile.command_plan(Command.START, control).writes[0]
    assert write == WriteCoils(0, words.words_to_coils([0x047C, 0x1999]))
    assert write.frame(1).encode() == frame('01 0F 00 00 00 20 04 7C 04 99 19 37 43')


def test_ramp_stop_is_the_manuals_frame():
    profile = FcProfileModbusDrive(fc51.DATA, 'fc51')
    write = profile.command_plan(Command.STOP, FixedControl()).writes[0]
    assert write.frame(1).encode() == frame('01 0F 00 00 00 20 04 3C 04 00 00 89 19')


def test_status_word_0607_from_coils_33_to_48():
    # Manual 004 section 5.5.1: reading coils 33-48 returns data bytes 07 06 = STW 0x0607.
    request = rtu.read_coils_request(1, 32, 16).encode()
    assert request[:6] == frame('01 01 00 20 00 10') and crc.crc_ok(request)
    coils = [bool(byte >> bit & 1) for byte in (0x07, 0x06) for bit in range(8)]
    assert words.coils_to_words(coils) == [0x0607]
    status = StatusWord(0x0607)
    assert status.flag(fc_profile.STW_CONTROL_READY) and status.flag(fc_profile.STW_UNIT_READY)
    assert status.flag(fc_profile.STW_ENABLED) and status.bus_control
    assert not status.tripped and not status.flag(fc_profile.STW_RUNNING)
    assert status.state(None, False) == 'ready'


def test_parameter_register_addresses_of_the_manual():
    assert fc51.DATA.spec(342).address == 0x0D5B  # 5.5.4: PNU 342 -> 0x0D5B
    assert fc51.DATA.spec(3).address == 0x001D  # 5.5.5: PNU 3 -> 0x001D
    assert fc51.DATA.spec(734).address == 0x1CAB  # 5.5.6: PNU 734 -> 0x1CAB
    assert fc51.DATA.spec(1614).address == 16139  # protocols.md: 16-14 -> 0x3F0B


def test_parameter_plans_encode_to_the_manuals_frames():
    profile = FcProfileModbusDrive(fc51.DATA, 'fc51')
    read = profile.parameter_plan(342)
    assert read.transactions == (ReadRegisters(0x0D5B, 2),)
    assert rtu.read_registers_request(1, 0x0D5B, 2).encode()[:6] == frame('01 03 0D 5B 00 02')
    assert read.decode([[0x0000, 0x0003]]) == pytest.approx(0.03)  # conversion index -2
    write_pnu3 = profile.parameter_plan(3, 1)
    assert write_pnu3.transactions == (WriteCoil(64, False), WriteRegister(0x001D, 1))
    assert rtu.write_register_request(1, 0x1D, 1).encode()[:6] == frame('01 06 00 1D 00 01')
    write_734 = profile.parameter_plan(734, 655.35, ParameterOptions(eeprom=True))
    assert write_734.transactions == (WriteCoil(64, True), WriteRegisters(0x1CAB, (0, 0xFFFF)))
    encoded = rtu.write_registers_request(1, 0x1CAB, [0, 0xFFFF]).encode()
    assert encoded[:11] == frame('01 10 1C AB 00 02 04 00 00 FF FF')
    current = profile.parameter_plan(1614)
    encoded = rtu.read_registers_request(1, current.transactions[0].address, 2).encode()
    assert encoded == frame('01 03 3F 0B 00 02 B9 DD')


def test_parameter_values_types_and_conversion():
    spec = fc51.DATA.spec(1614)  # int32, conversion -2
    assert decode_value(spec, [0xFFFF, 0xFF9C], FC_CONVERSION_FACTORS) == pytest.approx(-1.0)
    assert encode_value(spec, 2.25, FC_CONVERSION_FACTORS) == [0, 225]
    hours = fc51.DATA.spec(1500)  # conversion 74: raw is hours on the FC series
    assert decode_value(hours, [0, 1234], FC_CONVERSION_FACTORS) == 1234
    with pytest.raises(CommandRefused, match='out of range'):
        encode_value(fc51.DATA.spec(804), 300, FC_CONVERSION_FACTORS)
    with pytest.raises(CommandRefused, match='not a multiple'):
        encode_value(fc51.DATA.spec(341), 1.234, FC_CONVERSION_FACTORS)
    text = fc51.DATA.spec(1540)
    assert decode_value(text, words.text_to_registers('FC-051', 20), {}) == 'FC-051'
    with pytest.raises(CommandRefused, match='give its data type'):
        fc51.DATA.spec(999)
    assert fc51.DATA.spec(999, 'int16', -1).name == 'parameter (par. 9-99)'


# -- control profile ---------------------------------------------------------------------
def test_command_words():
    assert fc_profile.COMMAND_WORDS == {
        Command.START: 0x047C, Command.STOP: 0x043C, Command.QUICK_STOP: 0x042C,
        Command.COAST_STOP: 0x0434}
    for word in fc_profile.COMMAND_WORDS.values():
        assert word & (1 << fc_profile.CTW_DATA_VALID)
    assert fc_profile.is_start(0x047C) and not fc_profile.is_start(0x043C)
    assert fc_profile.with_reset(0x043C) == 0x04BC


@pytest.mark.parametrize('word, commanded, reached, state', [
    (0x0607 | 1 << 3, True, False, 'tripped'),
    (0x0607 | 1 << 6, None, False, 'tripped'),
    (0x0206, None, False, 'not_ready'),
    (0x0607, None, False, 'ready'),
    (0x0E07, True, False, 'starting'),
    (0x0F07, True, False, 'running'),
    (0x0E07, True, True, 'running'),  # a new reference after the start: still running
    (0x0E07, False, False, 'stopping'),
    (0x0E07, None, False, 'running'),  # started by terminals: the bridge sent nothing
    (0x0C07, True, False, 'running'),  # local operation: running, whatever the bridge sent
])
def test_status_word_states(word, commanded, reached, state):
    assert StatusWord(word).state(commanded, reached) == state


# -- drive profile -----------------------------------------------------------------------
def status_coils(status_word, actual_word=0):
    return list(words.words_to_coils([status_word, actual_word]))


def run_poll(profile, answers, control=None):
    """Run one poll cycle, answering each request by the readout it reads (``answers``)."""
    by_request = {ReadCoils(32, 32): 'status'}
    for key, number in (('drive_type', 1540), ('software_version', 1543)):
        by_request[FcProfileModbusDrive._read(fc51.DATA.spec(number))] = key
    for name, spec in profile.readouts.items():
        by_request[FcProfileModbusDrive._read(spec)] = name
    keys = []

    def answer(request):
        key = by_request.get(request, 'keepalive' if request.writes else '?')
        keys.append(key)
        if key not in answers and isinstance(request, ReadRegisters):
            return [0] * request.count  # a readout the test does not care about
        return answers.get(key)
    requests, reading = drive_cycle(profile, answer, control)
    return list(zip(keys, requests)), reading


IDENTITY = {'drive_type': words.text_to_registers('FC-051PK75T4E20H3', 20)[:9],
            'software_version': words.text_to_registers('2.70', 4)}


def test_nothing_is_written_without_a_command_in_force_then_keepalive_every_poll():
    profile = FcProfileModbusDrive(fc51.DATA, 'auto')
    items, reading = run_poll(profile, {'status': status_coils(0x0607), **IDENTITY,
                                        'motor_current': [0, 0]})
    assert not any(request.writes for _, request in items)
    assert [key for key, _ in items][:2] == ['drive_type', 'software_version']
    assert profile.model == 'fc51' and reading.details['drive_type'] == 'FC-051PK75T4E20H3'
    assert reading.state == 'ready'
    running = FixedControl(Command.START, profile.reference_word(-40.0))
    items, reading = run_poll(profile, {'status': status_coils(0x0E07, 0xF000),
                                        'motor_current': [0, 150]}, running)
    assert items[0] == ('keepalive', WriteCoils(0, words.words_to_coils([0x047C, 0xE667])))
    assert items[1] == ('status', ReadCoils(32, 32))
    assert reading.state == 'starting' and reading.motor_current_a == pytest.approx(1.5)
    assert reading.speed_feedback_pct == pytest.approx(-25.0)
    stopped = FixedControl(Command.STOP)
    items, _ = run_poll(profile, {'status': status_coils(0x0E07), 'motor_current': [0, 0]},
                        stopped)
    assert items[0] == ('keepalive', WriteCoils(0, words.words_to_coils([0x043C, 0])))


def test_the_keepalive_is_built_when_it_is_sent():
    """A command between two steps of a cycle changes what the next write carries."""
    profile = FcProfileModbusDrive(fc51.DATA, 'fc51')
    profile._identified = True

    class Switching(FixedControl):
        steady = Command.START
    control = Switching(reference_word=0x2000)
    cycle = profile.poll(control, 0.0)
    Switching.steady = Command.STOP  # a stop went out after the cycle began
    step = next(cycle)
    assert step.request == WriteCoils(0, words.words_to_coils([0x043C, 0x2000]))
    assert step.optional and not step.retry


def test_readouts_rotate_and_current_is_read_every_poll():
    profile = FcProfileModbusDrive(fc51.DATA, 'fc51')
    profile._identified = True
    answers = {'status': status_coils(0x0607), 'motor_current': [0, 0], 'frequency': [0],
               'motor_thermal': [0], 'alarm_word': [0, 0], 'warning_word': [0, 0],
               'extended_status': [0, 0]}
    keys = [[key for key, _ in run_poll(profile, answers)[0]] for _ in range(5)]
    assert all(plan[:2] == ['status', 'motor_current'] and len(plan) == 3 for plan in keys)
    assert {plan[2] for plan in keys} == {'frequency', 'motor_thermal', 'alarm_word',
                                          'warning_word', 'extended_status'}


def test_trip_reads_the_alarm_word_in_the_same_poll():
    profile = FcProfileModbusDrive(fc51.DATA, 'fc51')
    profile._identified = True
    items, reading = run_poll(profile, {
        'status': status_coils(0x0608 | 0x80), 'motor_current': [0, 0],
        'alarm_word': [0, 1 << 5], 'warning_word': [0, 1 << 5],
        'frequency': [0], 'motor_thermal': [0], 'extended_status': [0, 0]})
    assert 'alarm_word' in [key for key, _ in items]
    assert reading.state == 'tripped'
    assert (reading.trip_code, reading.trip_name) == (13, 'Over current')
    assert reading.fault == 'tripped: Over current'
    assert reading.alarm_word == 32 and reading.warning_word == 32
    assert reading.details['warnings'] == 'Over current'


def test_unknown_alarm_bits_keep_their_bit_number_and_no_bit_is_code_unknown():
    profile = FcProfileModbusDrive(fc51.DATA, 'fc51')
    assert profile.trip_from_alarm_word(1 << 18) == (1018, 'alarm word bit 18')
    assert profile.trip_from_alarm_word(0)[0] == TRIP_CODE_UNKNOWN  # never 0 = not tripped


def test_reset_is_a_rising_edge_and_leaves_a_ramp_stop():
    profile = FcProfileModbusDrive(fc51.DATA, 'fc51')
    plan = profile.command_plan(Command.RESET, FixedControl(Command.START))
    assert [words.coils_to_words(list(w.values))[0] for w in plan.writes] == [0x04BC, 0x043C]


def test_local_operation_refuses_commands():
    profile = FcProfileModbusDrive(fc51.DATA, 'fc51')
    profile._identified = True
    _, reading = run_poll(profile, {'status': status_coils(0x0407), 'motor_current': [0, 0]})
    assert 'local operation' in ' '.join(reading.warnings)
    with pytest.raises(CommandRefused, match='local operation .* nothing sent'):
        profile.check_command(Command.START, reading)


@pytest.mark.parametrize('bad', [math.nan, math.inf, -math.inf, 200.0, -250.0, 'fast'])
def test_bad_references_are_refused(bad):
    profile = FcProfileModbusDrive(fc51.DATA, 'fc51')
    with pytest.raises(CommandRefused, match='nothing sent'):
        profile.reference_word(bad)


def test_model_mismatch_from_the_fc_type():
    profile = FcProfileModbusDrive(fc51.DATA, 'fc51')
    with pytest.raises(ModelMismatch, match="reports type 'FC-302P'"):
        run_poll(profile, {'status': status_coils(0x0607), 'motor_current': [0, 0],
                           'drive_type': words.text_to_registers('FC-302P', 8),
                           'software_version': [0x3120]})


def test_identity_that_cannot_be_read_does_not_block_the_drive():
    profile = FcProfileModbusDrive(fc51.DATA, 'auto')
    _, reading = run_poll(profile, {'status': status_coils(0x0607), 'motor_current': [0, 0],
                                    'drive_type': DeviceException(2),
                                    'software_version': DeviceException(2)})
    assert reading.state == 'ready' and profile.model == 'fc51'
    assert reading.details['drive_type'].startswith('not readable (illegal data address')


def test_setup_writes_the_control_word_timeout():
    assert FcProfileModbusDrive(fc51.DATA, 'fc51').setup_plan() == []
    profile = FcProfileModbusDrive(fc51.DATA, 'fc51', comms_timeout_s=1.5,
                                   comms_timeout_function=2)
    assert profile.setup_plan() == [WriteRegisters(8029, (0, 15)), WriteRegister(8039, 2)]


def test_exception_texts_with_register_7_detail():
    profile = FcProfileModbusDrive(fc51.DATA, 'fc51')
    assert profile.detail_request(4) == ReadRegisters(6, 1)
    assert profile.detail_request(2) is None
    text = profile.explain_exception(4, 17)
    assert text.startswith('data change in the parameter is not possible in the present mode')
    assert text.endswith('Modbus exception 04')
    assert 'illegal data address' in profile.explain_exception(2)


# -- the FC 51 model and its Modbus face ---------------------------------------------------
def make_model(**settings):
    return FcProfileModel(FcProfileSimConfig(ramp_up_s=2.0, ramp_down_s=1.0, **settings),
                          now_s=0.0)


def test_model_ramps_per_3_41_and_3_42_and_coasts_at_once():
    model = make_model()
    model.write_control(0x047C, 0x2000, 0.0)  # start at 50 %
    model.advance(0.5)
    assert model.output_pct == pytest.approx(25.0)  # 100 % in 2 s
    model.advance(1.0)
    assert model.output_pct == pytest.approx(50.0)
    assert StatusWord(model.status_word()).state(True, False) == 'running'
    model.write_control(0x043C, 0x2000, 1.0)
    model.advance(1.25)
    assert model.output_pct == pytest.approx(25.0)  # 100 % in 1 s
    model.write_control(0x0434, 0x2000, 1.25)
    model.advance(1.26)
    assert model.output_pct == 0.0 and model.motor_current_a() == 0.0


def test_model_ignores_control_without_data_valid_or_in_local_mode():
    model = make_model()
    model.write_control(0x047C & ~(1 << 10), 0x2000, 0.0)
    model.advance(1.0)
    assert model.output_pct == 0.0
    model.local_mode = True
    model.write_control(0x047C, 0x2000, 1.0)
    model.advance(2.0)
    assert model.output_pct == 0.0
    assert not StatusWord(model.status_word()).bus_control


def test_model_control_word_timeout_stops_or_trips():
    model = make_model(ctw_timeout_s=1.0, ctw_timeout_function=5)
    model.write_control(0x047C, 0x4000, 0.0)
    model.advance(0.9)
    assert not model.tripped
    model.advance(1.1)
    assert model.alarm_word == 1 << 4 and model.output_pct == 0.0
    model.write_control(0x04BC, 0x4000, 2.0)  # reset on the rising edge of bit 7
    assert model.alarm_word == 0


def test_model_trip_and_reset_edge():
    model = make_model()
    model.write_control(0x04BC, 0, 0.0)  # bit 7 already high: no edge later
    model.trip(5, 0.1)
    model.write_control(0x04BC, 0, 0.2)
    assert model.tripped
    model.write_control(0x043C, 0, 0.3)
    model.write_control(0x04BC, 0, 0.4)
    assert not model.tripped


def test_sim_answers_coils_registers_and_exceptions():
    device = FcProfileModbusDevice(make_model())
    reply = device.handle(rtu.write_coils_request(1, 0, list(
        words.words_to_coils([0x047C, 0x1999]))), 0.0)
    assert reply.encode() == frame('01 0F 00 00 00 20 54 13')  # the manual's reply
    assert device.model.reference_word == 0x1999
    status = device.handle(rtu.read_coils_request(1, 32, 16), 0.0)
    assert status.data[0] == 2
    write_ro = device.handle(rtu.write_register_request(1, fc51.DATA.spec(1614).address, 1), 0)
    assert write_ro.function == 0x86 and write_ro.data == bytes([4])
    last_error = device.handle(rtu.read_registers_request(1, 6, 1), 0.0)
    assert last_error.data == bytes([2, 0, 1])  # detail 01: no write access
    missing = device.handle(rtu.read_registers_request(1, 10 * 999 - 1, 1), 0.0)
    assert missing.data == bytes([4])
    assert device.handle(rtu.RtuFrame(1, 0x2B, b'\x0e\x01\x00'), 0.0).data == bytes([1])
    with pytest.raises(ParameterError):
        device.model.write_parameter(804, [9], 0.0)


def test_a_start_read_before_the_drive_moves_is_still_starting_once_it_ramps():
    """A stopped drive reads "on reference" too: that must not end 'starting' before it began."""
    profile = FcProfileModbusDrive(fc51.DATA, 'fc51')
    started = FixedControl(Command.START, profile.reference_word(40.0))
    assert profile.reading(0x0703, 0, started).state == 'ready'  # start acknowledged, not yet
    assert profile.reading(0x0E07, 0x0400, started).state == 'starting'  # ramping
    assert profile.reading(0x0F07, 0x1999, started).state == 'running'  # on reference
    assert profile.reading(0x0E07, 0x1800, started).state == 'running'  # a later change


# -- the freshest information decides (issue 26) ---------------------------------------------
def slow_never_due():
    """Return slow readouts that are never due (for polls at time 0, as drive_cycle's)."""
    slow = SlowReadouts(1000.0)
    slow.due(0.0)  # the first poll that asks reads them: that one is gone
    return slow


def test_a_warning_word_read_during_a_warning_is_read_again_when_it_ends():
    profile = FcProfileModbusDrive(fc51.DATA, 'fc51', slow_readouts=slow_never_due())
    profile._identified = True
    answers = {'status': status_coils(0x0607 | 0x80), 'motor_current': [0, 0],
               'warning_word': [0, 1 << 5]}
    items, reading = run_poll(profile, answers)
    assert reading.warning_word == 32 and reading.details['warnings'] == 'Over current'
    # The warning bit clears: the warning word read during it is not published again.
    answers.update(status=status_coils(0x0607), warning_word=[0, 0])
    items, reading = run_poll(profile, answers)
    assert 'warning_word' in [key for key, _ in items]  # read again in this poll
    assert reading.warning_word == 0 and 'warnings' not in reading.details
    items, reading = run_poll(profile, answers)
    assert [key for key, _ in items] == ['status', 'motor_current']  # current: not again


def test_an_alarm_word_read_during_a_trip_is_read_again_after_the_reset():
    profile = FcProfileModbusDrive(fc51.DATA, 'fc51', slow_readouts=slow_never_due())
    profile._identified = True
    answers = {'status': status_coils(0x0608), 'motor_current': [0, 0],
               'alarm_word': [0, 1 << 5]}
    _, reading = run_poll(profile, answers)
    assert (reading.trip_code, reading.alarm_word) == (13, 32)
    answers.update(status=status_coils(0x0607), alarm_word=[0, 0])  # reset
    _, reading = run_poll(profile, answers)
    assert (reading.state, reading.trip_code, reading.alarm_word) == ('ready', 0, 0)


def test_a_start_with_a_0_percent_reference_reads_running_at_0_hz():
    """Manual 004 5.6.4: bit 11 is set by a start signal, bit 8 when the speed is the reference."""
    model = make_model()
    model.write_control(fc_profile.START_WORD, 0, 0.0)  # start, reference 0 %
    model.advance(1.0)
    status = StatusWord(model.status_word())
    assert model.output_pct == 0.0 and model.motor_current_a() == 0.0
    assert status.flag(fc_profile.STW_RUNNING) and status.flag(fc_profile.STW_ON_REFERENCE)
    profile = FcProfileModbusDrive(fc51.DATA, 'fc51')
    started = FixedControl(Command.START, 0)
    reading = profile.reading(model.status_word(), model.actual_word(), started)
    assert reading.state == 'running' and reading.speed_feedback_pct == 0.0
    model.write_control(fc_profile.RAMP_STOP_WORD, 0, 1.0)  # no start signal: ready
    assert profile.reading(model.status_word(), model.actual_word(),
                           FixedControl(Command.STOP)).state == 'ready'


def test_the_simulated_fc51_reports_the_line_it_is_served_on():
    served = FcProfileModel(FcProfileSimConfig(address=3, protocol='fc_protocol', baudrate=38400,
                                               parity='O', stopbits=1), now_s=0.0)
    assert [served.read_parameter(n, 1, 0.0) for n in (830, 831, 832, 833)] == [
        [0], [3], [4], [1]]
    with pytest.raises(ValueError, match='no par. 8-3x option for baud rate 1200: allowed'):
        FcProfileModel(FcProfileSimConfig(baudrate=1200), now_s=0.0)
