"""
Unit tests of reading a serialized ``std_msgs/Float32`` (``drive_bridge.ros.cdr``).

The oracle is rclpy's own serializer: every value it writes must read back the same, and no
byte string, cut short or garbled, may raise anything but MalformedMessage.
"""

import functools
import math
import random
import struct

import pytest

cdr = pytest.importorskip('drive_bridge.ros.cdr', reason='ROS 2 (rclpy) from PyPI')
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
    (b'\x01', '1 bytes, no CDR header'),
    (b'\x00\x01\x00\x00', '4 bytes end before the float at byte 4 (4 bytes)'),
    (b'\x00\x01\x00\x00\x00\x00\x20', '7 bytes end before the float at byte 4 (4 bytes)'),
    (b'\x7f\x7f\x00\x00\x00\x00\x20\x41', 'encapsulation 7f7f is not CDR'),
])
def test_bytes_that_are_no_float32_say_why_in_one_line(data, reason):
    with pytest.raises(cdr.MalformedMessage) as refused:
        cdr.read_float32(data)
    assert str(refused.value) == reason


def test_another_encapsulation_goes_to_rclpys_deserializer_and_its_refusal_is_malformed():
    with pytest.raises(cdr.MalformedMessage) as refused:
        cdr.read_float32(b'\x00\x03\x00\x00\x00\x00', DESERIALIZE)  # PL_CDR_LE, cut short
    assert str(refused.value).startswith('encapsulation 0003: ')
    assert '\n' not in str(refused.value)


def test_no_cut_or_garbled_float32_raises_anything_else():
    chance = random.Random(7)
    good = serialization.serialize_message(Float32(data=2.5))
    for cut in range(len(good)):
        with pytest.raises(cdr.MalformedMessage):
            cdr.read_float32(good[:cut], DESERIALIZE)
    for _ in range(500):
        garbled = bytes(chance.getrandbits(8) for _ in range(chance.randrange(0, 12)))
        try:
            cdr.read_float32(garbled, DESERIALIZE)
        except cdr.MalformedMessage:
            pass
