"""Unit tests of the pure codecs: CRC, RTU framing, words and FC scaling."""

import math

from drive_bridge.protocol import crc, fc_profile_scaling, rtu, words
import pytest


def hexbytes(text):
    return bytes.fromhex(text)


# Worked frames with CRCs from the VLT 5000/6000 Modbus RTU option card manual and the
# FC-series notes (shared/manuals/README.md, shared/research/protocols.md).
MANUAL_FRAMES = [
    '01 0F 00 00 00 20 04 7C 04 99 19 37 43',  # start at 40 %
    '01 0F 00 00 00 20 54 13',  # its reply
    '01 0F 00 00 00 20 04 3C 04 00 00 89 19',  # ramp stop
    '01 03 3F 0B 00 02 B9 DD',  # read 16-14 (motor current) from drive 1
]


@pytest.mark.parametrize('frame', MANUAL_FRAMES)
def test_crc_of_manual_frames(frame):
    data = hexbytes(frame)
    assert crc.append_crc(data[:-2]) == data
    assert crc.crc_ok(data)
    corrupted = bytes([data[0] ^ 1]) + data[1:]
    assert not crc.crc_ok(corrupted)


def test_crc_check_value_of_the_standard():
    # CRC-16/MODBUS catalogue check value for the ASCII digits 1-9.
    assert crc.crc16_modbus(b'123456789') == 0x4B37


def test_mcd_manual_examples_encode_to_frames():
    # Manual 000, section 8.1: starter address 20, register 40002 = 1 (start).
    start = rtu.write_register_request(20, 40002 - 40001, 1).encode()
    assert start[:6] == hexbytes('14 06 00 01 00 01') and crc.crc_ok(start)
    # Read 40003 (status), 40004 (trip code), 40009 (parameter 1).
    assert rtu.read_registers_request(20, 2, 1).encode()[:6] == hexbytes('14 03 00 02 00 01')
    assert rtu.read_registers_request(20, 3, 1).encode()[:6] == hexbytes('14 03 00 03 00 01')
    assert rtu.read_registers_request(20, 8, 1).encode()[:6] == hexbytes('14 03 00 08 00 01')
    # Write 40012 (parameter 4, current limit) = 400.
    write = rtu.write_register_request(20, 11, 400).encode()
    assert write[:6] == hexbytes('14 06 00 0B 01 90')


def test_decode_request_needs_more_bytes_then_frame():
    frame = rtu.read_registers_request(20, 2, 6).encode()
    for cut in range(len(frame)):
        assert rtu.decode_request(frame[:cut]) == rtu.DecodeResult()
    result = rtu.decode_request(frame + b'\x14')
    assert result.consumed == len(frame)
    assert result.frame == rtu.RtuFrame(20, 3, hexbytes('00 02 00 06'))


def test_decode_request_drops_crc_errors_and_truncated_frames():
    frame = bytearray(rtu.write_register_request(1, 1, 2).encode())
    frame[-1] ^= 0xFF
    assert rtu.decode_request(bytes(frame)).error == 'CRC error'
    assert rtu.decode_request(bytes(frame[:5]), gap_elapsed=True).error == 'truncated frame'


def test_decode_counted_and_unknown_functions():
    body = bytes([1, 0x0F, 0, 0, 0, 0x20, 4, 0x7C, 4, 0x99, 0x19])
    frame = crc.append_crc(body)
    assert rtu.decode_request(frame).frame.function == 0x0F
    unknown = crc.append_crc(bytes([1, 0x2B, 0x0E, 1, 0]))
    assert rtu.decode_request(unknown).consumed == 0  # waits for the gap
    assert rtu.decode_request(unknown, gap_elapsed=True).frame.function == 0x2B


def test_character_and_gap_times():
    assert rtu.character_bits('E', 1) == 11 and rtu.character_bits('N', 2) == 11
    assert rtu.character_time_s(9600, 'E', 1) == pytest.approx(11 / 9600)
    assert rtu.frame_gap_s(9600, 'E', 1) == pytest.approx(3.5 * 11 / 9600)
    assert rtu.frame_gap_s(38400) == 0.00175
    assert rtu.default_stopbits('N') == 2 and rtu.default_stopbits('E') == 1


def test_words():
    assert words.bits(0b1011_0110, 3, 7) == 0b10110
    assert words.bit(0x40, 6) and not words.bit(0x40, 5)
    assert words.to_signed16(0xC000) == -16384 and words.from_signed16(-16384) == 0xC000
    assert words.join_u32(*words.split_u32(0x12345678)) == 0x12345678
    with pytest.raises(ValueError):
        words.from_signed16(40000)


@pytest.mark.parametrize('percent, word', [
    (40.0, 0x1999),  # the VLT option card manual's example
    (100.0, 0x4000), (50.0, 0x2000), (0.0, 0x0000),
    (-200.0, 0x8000), (-100.0, 0xC000), (199.99, 0x7FFE), (-40.0, 0xE667),
])
def test_fc_scaling(percent, word):
    assert fc_profile_scaling.percent_to_word(percent) == word


@pytest.mark.parametrize('bad', [200.0, 250.0, -200.01, math.nan, math.inf, -math.inf])
def test_fc_scaling_rejects(bad):
    with pytest.raises(ValueError):
        fc_profile_scaling.percent_to_word(bad)


def test_fc_actual_value_decodes_signed():
    assert fc_profile_scaling.word_to_percent(0x4000) == 100.0
    assert fc_profile_scaling.word_to_percent(0xC000) == -100.0
    assert fc_profile_scaling.word_to_percent(0x1999) == pytest.approx(39.996, abs=1e-3)


def test_the_reply_framer_needs_more_bytes_until_the_reply_is_whole():
    # The VLT option card manual's reply to "start at 40 %": 01 0F 00 00 00 20 54 13.
    reply = hexbytes('01 0F 00 00 00 20 54 13')
    for cut in range(len(reply)):
        result = rtu.ReplyFramer.cut(reply[:cut])
        assert result.frame is None and not result.garbage and result.needed > cut
    frame = rtu.ReplyFramer.cut(reply).frame
    assert frame.valid and frame.unit == 1
    assert rtu.reply_frame(frame) == rtu.RtuFrame(1, 0x0F, hexbytes('00 00 00 20'))
    registers = rtu.registers_response(20, 3, [1, 2, 3]).encode()
    assert rtu.ReplyFramer.cut(registers[:3]).needed == len(registers)
    assert rtu.reply_frame(rtu.ReplyFramer.cut(registers).frame).data == \
        hexbytes('06 00 01 00 02 00 03')


def test_the_reply_framer_names_the_unit_and_tells_corrupt_frames_and_garbage():
    exception = rtu.exception_response(20, 6, 9).encode()
    assert rtu.reply_frame(rtu.ReplyFramer.cut(exception).frame).function == 0x86
    assert rtu.ReplyFramer.cut(rtu.exception_response(21, 6, 9).encode()).frame.unit == 21
    corrupted = exception[:-1] + bytes([exception[-1] ^ 1])
    spoiled = rtu.ReplyFramer.cut(corrupted).frame
    assert (spoiled.valid, spoiled.kind, spoiled.unit) == (False, 'crc', 20)
    assert rtu.ReplyFramer.cut(exception + b'\x00').frame.raw == exception  # the rest: later
    assert rtu.ReplyFramer.cut(b'\x14\x2b').garbage  # no function a reply carries
    assert rtu.ReplyFramer.cut(b'\x14\x99').needed == 5  # an exception, of function 19h
    assert rtu.ReplyFramer.cut(b'\x00\x03').garbage and rtu.ReplyFramer.cut(b'\xf8').garbage


def test_request_builders_of_the_manuals():
    assert rtu.write_coil_request(1, 64, True).encode()[:6] == hexbytes('01 05 00 40 FF 00')
    assert rtu.read_coils_request(1, 32, 32).encode()[:6] == hexbytes('01 01 00 20 00 20')
    assert rtu.pack_coils([True] + [False] * 7 + [True]) == hexbytes('01 01')
