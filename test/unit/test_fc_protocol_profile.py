"""Unit tests of the FC-protocol drive profile: one telegram per poll, commands, parameters."""

from drive_bridge.config.model import build_config
from drive_bridge.devices import fc51, vlt
from drive_bridge.devices.contracts import FixedControl, ParameterOptions, SlowReadouts
from drive_bridge.devices.fc_protocol_drive import FcProtocolDriveProfile
from drive_bridge.errors import CommandRefused, ConfigError, DeviceException
from drive_bridge.protocol import fc_telegram as fcp
from drive_bridge.protocol.commands import Command
from drive_bridge.protocol.fc_profile import RAMP_STOP_WORD, START_WORD
from fakes import drive_cycle
import pytest

READY, RUNNING, TRIPPED = 0x0607, 0x0F07, 0x0608


def answer(status=READY, actual=0, values=None):
    """Answer each telegram as a drive would: the status in PCD, the readout in PWE."""
    def reply(request):
        if request.ak == fcp.AK_TEXT:
            return fcp.FcTelegram(0x81, status, actual, fcp.make_pke(fcp.AK_REPLY_TEXT,
                                                                     request.pnu),
                                  request.ind, text=b'FC-051PK75T4E20H3BXC')
        value = (values or {}).get(request.pnu, 0)
        if isinstance(value, Exception):
            return DeviceException(value.args[0], 'refused',
                                   fcp.error_reply(request.telegram(1), value.args[0], status,
                                                   actual))
        return fcp.FcTelegram(0x81, status, actual, fcp.make_pke(fcp.AK_REPLY_DOUBLE,
                                                                 request.pnu), 0, value)
    return reply


def test_one_telegram_per_poll_and_nothing_valid_without_a_command():
    profile = FcProtocolDriveProfile(fc51.DATA, 'auto')
    requests, reading = drive_cycle(profile, answer(values={1614: 150}))
    assert [r.ak for r in requests] == [fcp.AK_TEXT, fcp.AK_TEXT, fcp.AK_READ]  # identity once
    assert profile.model == 'fc51' and reading.state == 'ready'
    assert not any(request.writes for request in requests)
    assert requests[-1].control_word == 0 and requests[-1].pnu == 1614
    assert reading.motor_current_a == pytest.approx(1.5)
    requests, _ = drive_cycle(profile, answer())
    assert len(requests) == 1  # identified: one telegram per poll from now on


def test_the_poll_telegram_carries_the_command_in_force_and_the_reference():
    profile = FcProtocolDriveProfile(fc51.DATA, 'fc51')
    profile._identified = True
    running = FixedControl(Command.START, profile.reference_word(40.0))
    requests, reading = drive_cycle(profile, answer(RUNNING, 0x1999), running)
    assert (requests[0].control_word, requests[0].reference) == (START_WORD, 0x1999)
    assert requests[0].writes and reading.speed_feedback_pct == pytest.approx(40.0, abs=0.01)
    stopped = FixedControl(Command.STOP)
    requests, _ = drive_cycle(profile, answer(), stopped)
    assert requests[0].control_word == RAMP_STOP_WORD


def test_readouts_current_every_other_poll_and_the_alarm_word_after_a_trip():
    profile = FcProtocolDriveProfile(fc51.DATA, 'fc51')
    profile._identified = True
    read = [drive_cycle(profile, answer())[0][0].pnu for _ in range(6)]
    assert read[0::2] == [1614, 1614, 1614] and 1614 not in read[1::2]
    drive_cycle(profile, answer(TRIPPED))  # the status shows the trip
    requests, reading = drive_cycle(profile, answer(TRIPPED, values={1690: 1 << 5}))
    assert requests[0].pnu == 1690 and (reading.trip_code, reading.trip_name) == \
        (13, 'Over current')


def test_a_refused_readout_keeps_the_status_of_its_reply():
    profile = FcProtocolDriveProfile(fc51.DATA, 'fc51')
    profile._identified = True
    requests, reading = drive_cycle(profile, answer(RUNNING, values={1614: Exception(0)}),
                                    FixedControl(Command.START))
    assert reading.state == 'running' and reading.motor_current_a is None
    assert 'motor_current_error' in reading.details


def test_the_vlt5000_vector_reads_par_520():
    profile = FcProtocolDriveProfile(vlt.DATA, 'vlt5000')
    requests, _ = drive_cycle(profile, answer())
    telegram = requests[0].telegram(1, fcp.ADDRESS_FORMAT_31)
    assert telegram.encode() == bytes.fromhex('02 0E 01 12 08 00 00 00 00 00 00 00 00 00 00 17')
    reply = fcp.decode(bytes.fromhex('02 0E 01 22 08 00 00 00 00 02 0C 06 07 00 00 28')).telegram
    fresh = FcProtocolDriveProfile(vlt.DATA, 'vlt5000')
    _, reading = drive_cycle(fresh, lambda request: reply)
    assert reading.motor_current_a == pytest.approx(5.24) and reading.status_word == 0x0607


def test_commands_are_process_telegrams_and_reset_leaves_a_ramp_stop():
    profile = FcProtocolDriveProfile(fc51.DATA, 'fc51')
    control = FixedControl(reference_word=0x2000)
    start = profile.command_plan(Command.START, control).writes
    assert start == (fcp.process_request(START_WORD, 0x2000),)
    vector = bytes.fromhex('02 06 04 04 7C')  # VLT 5000 Design Guide: start at 50 %
    assert start[0].telegram(4, fcp.ADDRESS_FORMAT_31).encode()[:5] == vector
    reset = profile.command_plan(Command.RESET, control).writes
    assert [w.control_word for w in reset] == [RAMP_STOP_WORD | 0x80, RAMP_STOP_WORD]


def test_parameters_by_pke_text_and_eeprom():
    profile = FcProtocolDriveProfile(fc51.DATA, 'fc51')
    read = profile.parameter_plan(341)
    assert read.transactions[0].ak == fcp.AK_READ and not read.transactions[0].writes
    write = profile.parameter_plan(341, 2.5, ParameterOptions(eeprom=True)).transactions[0]
    assert (write.ak, write.pwe, write.control_word) == (fcp.AK_WRITE_DOUBLE_EEPROM, 250, 0)
    text = profile.parameter_plan(1540).transactions[0]
    assert text.ak == fcp.AK_TEXT and text.ind == fcp.TEXT_READ_INDEX
    with pytest.raises(CommandRefused, match='out of range'):
        profile.parameter_plan(804, 300)
    assert 'not possible while running' in profile.explain_exception(17)


def test_setup_writes_8_03_and_8_04_by_the_parameter_channel():
    profile = FcProtocolDriveProfile(fc51.DATA, 'fc51', comms_timeout_s=1.5,
                                     comms_timeout_function=2)
    writes = profile.setup_plan()
    assert [(w.pnu, w.pwe) for w in writes] == [(803, 15), (804, 2)]
    assert all(w.control_word == 0 for w in writes)  # never a control word of their own


@pytest.mark.parametrize('device, message', [
    ({'family': 'vlt', 'model': 'vlt5000', 'comms_timeout': 1.0},
     'no option card register for it'),
    ({'family': 'vlt', 'model': 'vlt5000', 'drive_link_timeout': 1.0},
     "option card's register 3"),
    ({'family': 'fc', 'address': 127}, "out of range for protocol 'fc_protocol'"),
])
def test_configuration_errors_of_the_fc_protocol(device, message):
    with pytest.raises(ConfigError, match=message):
        build_config({'protocol': 'fc_protocol', 'devices': ['d']},
                     {'d': dict({'address': 1}, **device)})


def test_fc_protocol_defaults_are_8e1_with_a_two_character_gap():
    config = build_config({'protocol': 'fc_protocol', 'devices': ['d']},
                          {'d': {'family': 'fc', 'address': 1}})
    assert config.link.describe().endswith('9600 E1')
    assert config.timing.frame_gap_s == pytest.approx(2 * 11 / 9600)


def test_a_trip_is_not_named_by_the_alarm_word_of_an_earlier_one():
    slow = SlowReadouts(1000.0)
    slow.due(0.0)  # never due again at time 0 (drive_cycle's): the alarm word is read
    # only because of a trip
    profile = FcProtocolDriveProfile(fc51.DATA, 'fc51', slow_readouts=slow)
    profile._identified = True
    over_current, timeout = 1 << 5, 1 << 4
    drive_cycle(profile, answer(TRIPPED))  # the status shows the trip
    requests, reading = drive_cycle(profile, answer(TRIPPED, values={1690: over_current}))
    assert requests[0].pnu == 1690 and reading.trip_code == 13
    _, reset = drive_cycle(profile, answer(READY))  # reset
    # Another trip at once: the alarm word read during the first one does not name it.
    requests, reading = drive_cycle(profile, answer(TRIPPED, values={1690: timeout}))
    assert (reading.trip_code, reading.trip_name) == (17, 'Control word timeout')
    assert requests[0].pnu == 1690  # asked for again as soon as the first trip ended
    assert reset.trip_code == 0 and reset.alarm_word is None  # read before the reset


def test_a_warning_word_read_during_a_warning_is_not_published_after_it():
    profile = FcProtocolDriveProfile(fc51.DATA, 'fc51')
    profile._identified = True
    warning = READY | 0x80
    drive_cycle(profile, answer(warning))  # the status shows the warning
    requests, reading = drive_cycle(profile, answer(warning, values={1692: 1 << 5}))
    assert requests[0].pnu == 1692 and reading.warning_word == 32
    _, reading = drive_cycle(profile, answer(READY))  # the warning ends
    assert reading.warning_word is None and 'warnings' not in reading.details
    requests, reading = drive_cycle(profile, answer(READY))
    assert requests[0].pnu == 1692 and reading.warning_word == 0  # read again at once
