"""Unit tests of the VLT 5000/6000 option card profile: the manual's examples 1-6 and tables."""

from drive_bridge.config import model as config
from drive_bridge.devices import vlt
from drive_bridge.devices.contracts import FixedControl, ParameterOptions, SlowReadouts
from drive_bridge.devices.fc_profile_drive import FcProfileModbusDrive
from drive_bridge.devices.parameters import decode_value
from drive_bridge.errors import CommandRefused, ConfigError
from drive_bridge.protocol import crc, rtu, words
from drive_bridge.protocol.commands import Command
from drive_bridge.protocol.requests import ReadRegisters, WriteCoil, WriteRegister
from drive_bridge.sim.fc_profile_modbus_device import FcProfileModbusDevice
from drive_bridge.sim.fc_profile_model import FcProfileModel, FcProfileSimConfig
from fakes import drive_cycle
import pytest


def frame(text):
    return bytes.fromhex(text)


def encode(unit, request):
    """Return the RTU request frame of one request, CRC included."""
    return request.frame(unit).encode()


@pytest.fixture
def profile():
    return FcProfileModbusDrive(vlt.DATA, 'vlt6000')


def test_example_1_start_at_40_percent_and_its_reply(profile):
    control = FixedControl(reference_word=profile.reference_word(40.0))
    request = encode(1, profile.command_plan(Command.START, control).writes[0])
    assert request == frame('01 0F 00 00 00 20 04 7C 04 99 19 37 43')
    device = FcProfileModbusDevice(FcProfileModel(FcProfileSimConfig(model='vlt6000')))
    reply = device.handle(rtu.decode_request(request).frame, 0.0)
    assert reply.encode() == frame('01 0F 00 00 00 20 54 13')


def test_example_2_ramp_stop(profile):
    assert encode(1, profile.command_plan(Command.STOP, FixedControl()).writes[0]) == \
        frame('01 0F 00 00 00 20 04 3C 04 00 00 89 19')


def test_example_3_coast_stop():
    # The manual's coast word 0x2C20 also sets relay 1 (bit 11) and set-up bit 13; the
    # bridge's coast (0x0434) clears only the coast bit and leaves relays and set-ups alone.
    manual = rtu.write_coils_request(1, 0, list(words.words_to_coils([0x2C20, 0]))).encode()
    assert manual[:11] == frame('01 0F 00 00 00 20 04 20 2C 00 00') and crc.crc_ok(manual)
    coast = FcProfileModbusDrive(vlt.DATA, 'vlt5000').command_plan(Command.COAST_STOP,
                                                                   FixedControl()).writes[0]
    assert words.coils_to_words(list(coast.values))[0] == 0x0434
    assert not 0x0434 & (1 << 3)  # bit 3 = 0: coast


def test_example_4_write_104_motor_frequency_60_hz(profile):
    plan = profile.parameter_plan(104, 60)
    assert plan.transactions == (WriteCoil(64, False), WriteRegister(0x040F, 60))
    assert encode(1, plan.transactions[1])[:6] == frame('01 06 04 0F 00 3C')


def test_example_5_read_514_motor_current_3_a(profile):
    plan = profile.parameter_plan(514)
    assert plan.transactions == (ReadRegisters(0x1413, 2),)
    assert encode(1, plan.transactions[0])[:6] == frame('01 03 14 13 00 02')
    assert plan.decode([[0x0000, 0x012C]]) == pytest.approx(3.0)


def test_example_6_text_write_of_533(profile):
    plan = profile.parameter_plan(533, '1234567890')
    coil, text_mode, text, cleared = plan.transactions
    assert coil == WriteCoil(64, False)
    assert encode(1, text_mode)[:6] == frame('01 06 00 00 05 00')
    assert encode(1, text)[:17] == frame('01 10 14 D1 00 05 0A 31 32 33 34 35 36 37 38 39 30')
    assert cleared == WriteRegister(0, 0)  # IND cleared after the text access
    read = profile.parameter_plan(533)
    assert read.transactions == (WriteRegister(0, 0x0400), ReadRegisters(5329, 10, exact=False),
                                 WriteRegister(0, 0))
    assert read.decode([None, words.text_to_registers('HELLO', 6), None]) == 'HELLO'
    with pytest.raises(CommandRefused, match='longer than 20'):
        profile.parameter_plan(533, 'x' * 21)


def test_conversion_index_74_is_3_6_here():
    spec = vlt.DATA.spec(999, 'uint16', 74)
    assert decode_value(spec, [10], vlt.DATA.conversion_factors) == pytest.approx(36.0)


def test_readouts_per_model_and_override():
    assert FcProfileModbusDrive(vlt.DATA, 'vlt6000').readouts['motor_current'].number == 514
    assert FcProfileModbusDrive(vlt.DATA, 'vlt5000').readouts['motor_current'].number == 520
    override = FcProfileModbusDrive(vlt.DATA, 'vlt5000', readout_overrides={'motor_current': 514})
    assert override.readouts['motor_current'].number == 514
    assert set(override.readouts) == {'motor_current', 'alarm_word', 'warning_word',
                                      'extended_status'}


def test_exception_codes_of_the_option_card(profile):
    assert profile.detail_request(4) is None  # no register 7 on the option card
    assert profile.explain_exception(4) == \
        'the parameter is not of the array type, Modbus exception 04'
    assert profile.explain_exception(131).startswith('data change is not possible because')
    assert 'message timeout' in profile.explain_exception(255)
    assert profile.explain_exception(67).startswith('invalid function code')
    for code in (0, 1, 2, 3, 5, 17, 130, 64, 65, 66):
        assert 'not in the option card manual' not in profile.explain_exception(code)


def test_comms_timeouts_go_to_registers_2_and_3_in_10_ms_units():
    profile = FcProfileModbusDrive(vlt.DATA, 'vlt6000', comms_timeout_s=1.5)
    assert profile.setup_plan() == [WriteRegister(1, 150)]
    both = FcProfileModbusDrive(vlt.DATA, 'vlt6000', comms_timeout_s=1.5, drive_link_timeout_s=0.5)
    assert both.setup_plan() == [WriteRegister(1, 150), WriteRegister(2, 50)]
    with pytest.raises(ConfigError, match='up to 655.35 s'):
        FcProfileModbusDrive(vlt.DATA, 'vlt6000', comms_timeout_s=700.0)


def test_index_register_is_ind(profile):
    plan = profile.parameter_plan(999, options=ParameterOptions(data_type='uint16', index=3))
    assert plan.transactions[0] == WriteRegister(0, 3)


@pytest.mark.parametrize('device, message', [
    ({}, "'fan.model' = 'auto' is invalid for family vlt (this family cannot report its "
         'model: name it): allowed vlt5000, vlt6000'),
    ({'model': 'vlt6000', 'comms_timeout_function': 2},
     "parameter 'fan.comms_timeout_function' applies to families fc only, not vlt"),
    ({'family': 'fc', 'model': 'fc51', 'drive_link_timeout': 1.0},
     "parameter 'fan.drive_link_timeout' applies to families vlt only, not fc"),
])
def test_vlt_configuration_errors(device, message):
    with pytest.raises(ConfigError) as error:
        config.build_config({'devices': ['fan']},
                            {'fan': {'family': 'vlt', 'address': 1, **device}})
    assert message in str(error.value)


def test_option_card_sim_exceptions_and_text_mode():
    device = FcProfileModbusDevice(FcProfileModel(FcProfileSimConfig(model='vlt6000')))
    missing = device.handle(rtu.read_registers_request(1, 10 * 999 - 1, 1), 0.0)
    assert missing.function == 0x83 and missing.data == bytes([0])
    text_without_ind = device.handle(rtu.read_registers_request(1, 5329, 10), 0.0)
    assert text_without_ind.data == bytes([5])  # data type does not match
    assert device.handle(rtu.write_register_request(1, 0, 0x0400), 0.0) is not None
    assert device.handle(rtu.read_registers_request(1, 5329, 10), 0.0).function == 3
    assert device.handle(rtu.RtuFrame(1, 0x2B, b'\x0e\x01\x00'), 0.0).data == bytes([67])
    assert device.handle(rtu.write_register_request(1, 1, 200), 0.0) is not None
    assert device.model.card_timeouts == [200, 0]


def test_the_alarm_word_agrees_with_the_simulated_drive_after_a_reset():
    """A stale alarm word is never published: after a reset it is read again (issue 26)."""
    slow = SlowReadouts(1000.0)
    slow.due(0.0)  # never due again at time 0 (drive_cycle's): the alarm word is read
    # only because of the trip bits
    profile = FcProfileModbusDrive(vlt.DATA, 'vlt6000', slow_readouts=slow)
    device = FcProfileModbusDevice(FcProfileModel(FcProfileSimConfig(model='vlt6000')))

    def answer(request):
        sent = request.frame(1)
        return request.parse(sent, device.handle(sent, 0.0))
    device.model.trip(5, 0.0)
    _, reading = drive_cycle(profile, answer)
    assert (reading.trip_code, reading.alarm_word) == (1005, device.model.alarm_word)
    for step in profile.command_plan(Command.RESET, FixedControl()).writes:
        answer(step)
    assert device.model.alarm_word == 0
    _, reading = drive_cycle(profile, answer)
    assert (reading.state, reading.trip_code, reading.alarm_word) == ('ready', 0, 0)
