"""Unit tests of the AP ASCII codec (every worked frame) and the MCD AP ASCII profile."""

from drive_bridge.devices.contracts import FixedControl, SlowReadouts
from drive_bridge.devices.mcd_ascii import McdAsciiProfile
from drive_bridge.errors import CommandRefused, ProtocolError
from drive_bridge.protocol import ap_ascii
from drive_bridge.protocol.commands import Command
from drive_bridge.protocol.requests import AsciiCommand, AsciiRequest
from fakes import drive_cycle
import pytest


def frame(text):
    return bytes.fromhex(text)


@pytest.mark.parametrize('code, expected', [
    ('B10', '02 42 31 30 35 42 03'),  # manual 000 section 10.4 and 001: start, LRC 5Bh
    ('B12', '02 42 31 32 35 39 03'), ('B14', '02 42 31 34 35 37 03'),
    ('B16', '02 42 31 36 35 35 03'), ('B18', '02 42 31 38 35 33 03'),
    ('C22', '02 43 32 32 35 37 03'), ('C18', '02 43 31 38 35 32 03'),
    ('D10', '02 44 31 30 35 39 03'), ('D12', '02 44 31 32 35 37 03'),
])
def test_worked_frames(code, expected):
    assert ap_ascii.message_fragment(code) == frame(expected)


def test_lrc_worked_example_step_by_step():
    body = frame('02 42 31 30')
    assert sum(body) % 256 == 0xA5  # sum, mod 256
    assert ap_ascii.lrc(body) == 0x5B  # two's complement
    assert ap_ascii.lrc_ascii(body) == b'5B'
    # 001, "To verify a received message": the bytes plus the LRC sum to zero.
    assert ap_ascii.lrc_matches(body, b'5B')
    assert not ap_ascii.lrc_matches(body, b'5C')
    assert not ap_ascii.lrc_matches(body, b'Z!')


def test_address_fragment_with_and_without_eot_in_the_lrc():
    assert ap_ascii.address_fragment(20) == frame('04 32 30 39 41 05')
    assert ap_ascii.address_fragment(20, lrc_includes_eot=False) == frame('04 32 30 39 45 05')
    assert ap_ascii.address_fragment(1)[1:3] == b'01'
    with pytest.raises(ValueError):
        ap_ascii.address_fragment(100)
    for fragment in (frame('04 32 30 39 41 05'), frame('04 32 30 39 45 05')):
        decoded, consumed = ap_ascii.decode_fragment(fragment)
        assert consumed == 6 and decoded.address == 20 and decoded.lrc_ok
    strict, _ = ap_ascii.decode_fragment(frame('04 32 30 39 41 05'), lrc_includes_eot=False)
    assert not strict.lrc_ok


def test_status_1f_as_the_manual_sends_it():
    assert ap_ascii.data_fragment(ap_ascii.encode_status(0x1F)) == \
        frame('02 30 30 31 46 32 37 03')
    assert ap_ascii.decode_status(b'001F') == 0x1F
    assert ap_ascii.encode_status(0x1F, 'offset') == b'001?'  # 30h + nibble
    assert ap_ascii.decode_status(b'001?') == 0x1F
    with pytest.raises(ValueError):
        ap_ascii.decode_status(b'011F')


def test_data_digits():
    assert ap_ascii.encode_data(105) == b'0105'  # the thermal model's trip point
    assert ap_ascii.decode_data(b'9999') == 9999
    for bad in (b'12a4', b'123'):
        with pytest.raises(ValueError):
            ap_ascii.decode_data(bad)


def test_reply_framer_need_more_bytes_and_errors():
    framer = ap_ascii.ReplyFramer
    reply = ap_ascii.data_fragment(b'0080')
    assert framer.cut(b'').needed == 1
    for cut in range(1, len(reply)):
        assert framer.cut(reply[:cut]).needed == 8
    frame = framer.cut(reply).frame
    assert frame.valid and frame.unit is None and ap_ascii.reply_kind(frame) == 'frame'
    assert frame.raw[1:5] == b'0080'
    for byte, kind in ((0x06, 'ACK'), (0x15, 'NAK'), (0x07, 'BEL')):
        assert ap_ascii.reply_kind(framer.cut(bytes([byte])).frame) == kind
    bad_lrc = reply[:5] + b'00' + reply[-1:]
    assert framer.cut(bad_lrc).frame.error == 'LRC error in the reply'
    assert framer.cut(b'\x41').garbage
    assert framer.cut(b'\x06\x06').frame.raw == b'\x06'  # the second: another frame


def test_profile_requests_and_commands():
    profile = McdAsciiProfile('mcd500')
    requests, _ = drive_cycle(profile, [0x41, 255, 0, 0])
    assert requests == [AsciiRequest('C22', 'status'), AsciiRequest('C18', 'status'),
                        AsciiRequest('D10', 'data'), AsciiRequest('D12', 'data')]
    requests, _ = drive_cycle(McdAsciiProfile('mcd201'), [0x41, 255])
    assert requests == [AsciiRequest('C22', 'status'), AsciiRequest('C18', 'status')]
    control = FixedControl()
    assert profile.command_plan(Command.START, control).writes == (AsciiCommand('B10'),)
    assert profile.command_plan(Command.QUICK_STOP, control).writes == (AsciiCommand('B16'),)
    assert profile.command_plan(Command.FORCED_COMMS_TRIP, control).writes == \
        (AsciiCommand('B18'),)
    with pytest.raises(CommandRefused):
        profile.command_plan(Command.COAST_STOP, control)
    with pytest.raises(CommandRefused, match='MCD 3000 has none'):
        McdAsciiProfile('mcd3000').command_plan(Command.FORCED_COMMS_TRIP, control)
    with pytest.raises(CommandRefused, match='no parameter access'):
        profile.parameter_plan(1)


def test_profile_decode_states_trips_and_comms_fault():
    profile = McdAsciiProfile('mcd500')
    _, reading = drive_cycle(profile, [0x43, 255, 80, 40])
    assert reading.state == 'running' and reading.trip_code == 0 and reading.trip_name == ''
    assert reading.motor_current_a == 80.0 and reading.motor_temperature_pct == 40.0
    _, tripped = drive_cycle(profile, [0x46, 2, 0, 106])
    assert (tripped.state, tripped.trip_code) == ('tripped', 2)
    assert tripped.trip_name == 'Motor overload (thermal model)'
    _, fault = drive_cycle(profile, [0xC1, 255, 0, 0])
    assert fault.fault.startswith('communications device fault (C22 bit 7)')
    with pytest.raises(ProtocolError):
        drive_cycle(profile, [None, 255, 0, 0])


def test_mcd3000_has_its_own_trip_table():
    profile = McdAsciiProfile('mcd3000')
    assert profile.trip(2) == (2, 'Overcurrent')
    assert profile.trip(0) == (256, 'Shorted SCR')  # 0 would read as "not tripped"
    assert profile.trip(255) == (0, '')
    assert McdAsciiProfile('mcd500').trip(2) == (2, 'Motor overload (thermal model)')
    assert 'Hand On' in profile.explain_exception(ap_ascii.BEL)


def test_a_trip_code_is_taken_only_from_the_poll_that_asks_for_it():
    # Issue 26's audit: the trip code (C18) is the MCD's only slow readout over AP ASCII. It is
    # asked for in every poll whose status shows a trip, after the status; in the others it
    # is not, and the trip read before never names the state of a later poll.
    profile = McdAsciiProfile('mcd500', slow_readouts=SlowReadouts(10.0))
    drive_cycle(profile, [0x43, 255, 80, 40])  # the slow readouts' turn: C18 asked
    requests, tripped = drive_cycle(profile, [0x46, 2, 0, 106], now_s=1.0)
    assert requests[:2] == [AsciiRequest('C22', 'status'), AsciiRequest('C18', 'status')]
    assert (tripped.state, tripped.trip_code) == ('tripped', 2)
    requests, reset = drive_cycle(profile, [0x41, 0, 100])  # reset at the starter
    assert AsciiRequest('C18', 'status') not in requests
    assert (reset.state, reset.trip_code, reset.trip_name) == ('ready', 0, '')
    _, again = drive_cycle(profile, [0x46, 3, 0, 100])  # another trip: its own code
    assert (again.state, again.trip_code) == ('tripped', 3)
