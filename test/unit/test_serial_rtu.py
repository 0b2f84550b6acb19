"""The native RTU engine: late replies before and after the reply asked for."""

from drive_bridge.errors import BadFrame, CrcError, FAILURE_KINDS, TruncatedFrame, WrongAddress
from drive_bridge.protocol import rtu
from drive_bridge.protocol.requests import ReadRegisters, WriteRegister
from drive_bridge.transport.link import LinkSettings
from drive_bridge.transport.serial_rtu import RtuSerialTransport
from fakes import ScriptedPort
import pytest


def transport_with(reply: bytes) -> RtuSerialTransport:
    transport = RtuSerialTransport(LinkSettings(port='/dev/null', timeout_s=0.05))
    transport._port = ScriptedPort(reply)
    return transport


def registers_reply(unit: int, values) -> bytes:
    data = bytes([2 * len(values)]) + b''.join(v.to_bytes(2, 'big') for v in values)
    return rtu.RtuFrame(unit, 3, data).encode()


LATE_FROM_ANOTHER_DEVICE = registers_reply(21, [7, 8, 9])
LATE_POLL_OF_THIS_DEVICE = registers_reply(20, [1, 2, 3, 4])
WRITE_ECHO = rtu.write_register_request(20, 1, 1).encode()


@pytest.mark.parametrize('late', [LATE_FROM_ANOTHER_DEVICE, LATE_POLL_OF_THIS_DEVICE])
def test_a_late_reply_before_the_reply_asked_for_is_dropped_and_counted(late):
    transport = transport_with(late + WRITE_ECHO)
    assert transport.execute(20, WriteRegister(1, 1)) is None
    assert transport.last_recovered == {'late_reply': 1}
    assert 'late_reply' in FAILURE_KINDS  # /diagnostics lists it as errors_late_reply


def test_a_frame_from_another_address_and_nothing_after_it_is_a_wrong_address():
    transport = transport_with(LATE_FROM_ANOTHER_DEVICE)
    with pytest.raises(WrongAddress, match='no other within'):
        transport.execute(20, ReadRegisters(0, 3))


def test_a_frame_with_another_function_and_nothing_after_it_is_a_bad_frame():
    transport = transport_with(LATE_POLL_OF_THIS_DEVICE)
    with pytest.raises(BadFrame, match='function 03h to a 06h request'):
        transport.execute(20, WriteRegister(1, 1))


def test_a_frame_from_another_address_with_a_bad_crc_is_a_wrong_address():
    corrupted = LATE_FROM_ANOTHER_DEVICE[:-1] + bytes([LATE_FROM_ANOTHER_DEVICE[-1] ^ 0xFF])
    transport = transport_with(corrupted)
    with pytest.raises(WrongAddress):
        transport.execute(20, ReadRegisters(0, 3))
    assert transport.last_recovered == {}


def test_the_counter_starts_again_with_each_transaction():
    transport = transport_with(LATE_FROM_ANOTHER_DEVICE + registers_reply(20, [5, 6, 7]))
    assert transport.execute(20, ReadRegisters(0, 3)) == [5, 6, 7]
    transport._port = ScriptedPort(registers_reply(20, [5, 6, 7]))
    assert transport.execute(20, ReadRegisters(0, 3)) == [5, 6, 7]
    assert transport.last_recovered == {}


NEWER = registers_reply(20, [5, 6, 7])


def test_of_replies_back_to_back_the_last_whole_one_is_taken():
    transport = transport_with(registers_reply(20, [1, 2, 3]) + LATE_FROM_ANOTHER_DEVICE + NEWER)
    assert transport.execute(20, ReadRegisters(0, 3)) == [5, 6, 7]
    assert transport.last_recovered == {'late_reply': 2}


@pytest.mark.parametrize('stray', [b'\x00', b'\xff\xff', b'\x15\x03'])
def test_bytes_that_begin_no_reply_of_the_unit_leave_the_reply_as_it_is(stray):
    transport = transport_with(registers_reply(20, [1, 2, 3]) + stray)
    assert transport.execute(20, ReadRegisters(0, 3)) == [1, 2, 3]
    assert transport.last_recovered == {}


def test_a_second_reply_that_is_not_whole_fails_the_transaction():
    transport = transport_with(registers_reply(20, [1, 2, 3]) + NEWER[:6])
    with pytest.raises(TruncatedFrame, match='the first may be a late one'):
        transport.execute(20, ReadRegisters(0, 3))


def test_a_second_reply_with_a_crc_error_fails_the_transaction():
    transport = transport_with(registers_reply(20, [1, 2, 3]) + NEWER[:-1] + b'\x00')
    with pytest.raises(CrcError, match='the first may be a late one'):
        transport.execute(20, ReadRegisters(0, 3))


def test_bytes_waiting_before_the_request_are_counted_as_late_bytes():
    transport = transport_with(b'')
    transport._port = ScriptedPort(NEWER, early=True)  # there before the request was written
    assert transport.execute(20, ReadRegisters(0, 3)) == [5, 6, 7]
    assert transport.last_recovered == {'late_bytes': 1}


@pytest.mark.parametrize('buffer, expected', [
    (NEWER, (NEWER, 1, 0, False)),
    (registers_reply(20, [1]) + NEWER, (NEWER, 2, 0, False)),
    (NEWER + LATE_FROM_ANOTHER_DEVICE, (NEWER, 2, 0, False)),
    (LATE_FROM_ANOTHER_DEVICE, (None, 1, 0, False)),
    (NEWER + NEWER[:1], (NEWER, 1, len(NEWER) + 3, False)),
    (NEWER + NEWER[:4], (NEWER, 1, 2 * len(NEWER), False)),
    (NEWER + NEWER[:-1] + b'\x00', (NEWER, 1, 0, True)),
    (NEWER + b'\x00' + NEWER, (NEWER, 1, 0, False)),  # garbage ends the scan
    (rtu.exception_response(20, 3, 2).encode() + b'\x00',
     (rtu.exception_response(20, 3, 2).encode(), 1, 0, False)),
])
def test_newest_reply_scans_whole_frames_back_to_back(buffer, expected):
    newest = rtu.newest_reply(buffer, 20, 3)
    frame = newest.frame.encode() if newest.frame else None
    assert (frame, newest.frames, newest.needed, newest.spoiled) == expected
