"""
Unit tests of reading a serialized ``std_msgs/Float32`` (``drive_bridge.ros.node.cdr``).

The oracle is rclpy's own serializer: every value it writes must read back the same, and no
byte string, cut short or garbled, may raise anything but MalformedMessage.
"""

import functools
import math
import random
import struct

import pytest

cdr = pytest.importorskip('drive_bridge.ros.node.cdr', reason='ROS 2 (rclpy) from PyPI')
serialization = pytest.importorskip('rclpy.serialization')
Float32 = pytest.importorskip('std_msgs.msg').Float32
DESERIALIZE = functools.partial(serialization.deserialize_message, message_type=Float32)


def same(read: float, written: float) -> bool:
    return (math.isnan(read) and math.isnan(written)) or read == written


def test_what_rclpy_writes_reads_back_the_same():
    chance = random.Random(29)
    values = [0.0, -0.0, 1.5, -100.0, math.inf, -math.inf, math.nan, 3.4e38, 1e-45]
    values += [struct.unpack('<f', struct.pack('<I', chance.getrandbits(32)))[0]
               for _ in range(2000)]
    for value in values:
        data = serialization.serialize_message(Float32(data=value))
        written = struct.unpack('<f', struct.pack('<f', value))[0]  # as float32 holds it
        assert same(cdr.read_float32(data, DESERIALIZE), written), (value, data.hex())


@pytest.mark.parametrize('data, value', [
    (b'\x00\x01\x00\x00' + struct.pack('<f', 12.5), 12.5),
    (b'\x00\x00\x00\x00' + struct.pack('>f', -7.25), -7.25),  # big-endian
    (b'\x00\x01\x00\x00' + struct.pack('<f', 40.0) + b'\x00\x00\x00\x00', 40.0),  # padding
])
def test_both_byte_orders_and_trailing_padding_are_read(data, value):
    assert cdr.read_float32(data) == value


@pytest.mark.parametrize('data, reason', [
    (b'', '0 bytes, no CDR header'),
    (b'\x01', '1 byte, no CDR header'),
    (b'\x00\x01\x00\x00', '4 bytes end before the whole float, bytes 4-7'),
    (b'\x00\x01\x00\x00\x00\x00\x20', '7 bytes end before the whole float, bytes 4-7'),
    # The options say the last 2 bytes are padding: 2 bytes of a float are left.
    (b'\x00\x01\x00\x02\x00\x20\x00\x00', '8 bytes end before the whole float, bytes 4-7'),
    (b'\x7f\x7f\x00\x00\x00\x00\x20\x41', 'encapsulation 7f7f is not CDR'),
])
def test_bytes_that_are_no_float32_say_why_in_one_line(data, reason):
    with pytest.raises(cdr.MalformedMessage) as refused:
        cdr.read_float32(data)
    assert str(refused.value) == reason


def test_padding_the_options_count_is_skipped():
    assert cdr.read_float32(b'\x00\x01\x00\x03' + struct.pack('<f', 7.5) + b'\x00\x00\x00') == 7.5


def test_another_encapsulation_is_read_by_rclpys_deserializer():
    xcdr2 = b'\x00\x07\x00\x00' + struct.pack('<f', -12.25)
    assert DESERIALIZE(xcdr2).data == -12.25  # rclpy reads it: so must the node
    assert cdr.read_float32(xcdr2, DESERIALIZE) == -12.25


def test_another_encapsulation_refused_by_rclpy_is_malformed_in_one_short_line():
    with pytest.raises(cdr.MalformedMessage) as refused:
        cdr.read_float32(b'\x00\x03\x00\x00\x00\x00', DESERIALIZE)  # PL_CDR_LE, cut short
    reason = str(refused.value)
    assert reason.startswith('encapsulation 0003: ') and '\n' not in reason
    assert '.cpp' not in reason, reason  # rcl's source location is left out


def rclpys_answer(data: bytes):
    """Return what rclpy's typed deserializer makes of ``data``: the float, or None."""
    try:
        return DESERIALIZE(data).data
    except Exception:  # noqa: B902 - whatever it raises: it takes no message
        return None


def test_cut_or_garbled_bytes_read_as_rclpy_reads_them_or_are_malformed():
    chance = random.Random(7)
    good = serialization.serialize_message(Float32(data=2.5))
    for cut in range(len(good)):
        with pytest.raises(cdr.MalformedMessage):
            cdr.read_float32(good[:cut], DESERIALIZE)
    for attempt in range(3000):
        head = (b'\x00\x01', b'\x00\x00', bytes(chance.getrandbits(8) for _ in range(2)))[
            attempt % 3]
        garbled = head + bytes(chance.getrandbits(8) for _ in range(chance.randrange(0, 12)))
        expected = rclpys_answer(garbled)
        try:
            read = cdr.read_float32(garbled, DESERIALIZE)
        except cdr.MalformedMessage:
            read = None
        padded = len(garbled) >= 4 and garbled[:2] in cdr.ENCAPSULATIONS and garbled[3] & 3
        if read is None and expected is not None and padded:
            continue  # the options count padding that leaves no float: refused here only
        if read is None or expected is None:
            assert read is None and expected is None, (garbled.hex(), read, expected)
        else:
            assert same(read, expected), (garbled.hex(), read, expected)
