"""
Unit tests of reading serialized ``~/joint_commands`` (``drive_bridge.ros.node.joints.wire``).

The oracle is rclpy's own serializer: every message it writes must read back to the same
names and velocities, and no byte string, cut short or garbled, may raise anything but
MalformedCommand.
"""

import random
import struct

import pytest

wire = pytest.importorskip('drive_bridge.ros.node.joints.wire', reason='ROS 2 (rclpy) from PyPI')
serialization = pytest.importorskip('rclpy.serialization')
JointState = pytest.importorskip('sensor_msgs.msg').JointState


def serialized(**fields) -> bytes:
    message = JointState(**fields)
    return serialization.serialize_message(message)


def random_message(chance: random.Random) -> JointState:
    message = JointState()
    message.header.frame_id = 'f' * chance.randrange(0, 9)
    message.header.stamp.sec = chance.randrange(-2 ** 31, 2 ** 31)
    message.header.stamp.nanosec = chance.randrange(0, 10 ** 9)
    message.name = [''.join(chance.choice('abz_09é') for _ in range(chance.randrange(0, 12)))
                    for _ in range(chance.randrange(0, 10))]
    for field in ('position', 'velocity', 'effort'):
        setattr(message, field, [chance.uniform(-1e3, 1e3)
                                 for _ in range(chance.randrange(0, 10))])
    return message


def test_every_message_rclpy_writes_reads_back_to_its_names_and_velocities():
    chance = random.Random(29)
    for _ in range(2000):
        message = random_message(chance)
        command = wire.read_joint_command(serialization.serialize_message(message))
        assert command.name == tuple(message.name)
        assert command.velocity == tuple(message.velocity)


def test_a_message_cut_short_or_garbled_is_malformed_and_nothing_else():
    chance = random.Random(7)
    for _ in range(200):
        data = serialization.serialize_message(random_message(chance))
        for end in range(len(data)):
            try:
                wire.read_joint_command(data[:end])
            except wire.MalformedCommand:
                pass
        garbled = bytearray(data)
        for _ in range(3):
            garbled[chance.randrange(2, len(garbled))] = chance.randrange(256)
        try:
            wire.read_joint_command(bytes(garbled))
        except wire.MalformedCommand:
            pass


def test_the_end_of_a_message_is_needed():
    data = serialized(name=['left', 'right'], velocity=[1.0, 2.0], effort=[3.0])
    with pytest.raises(wire.MalformedCommand, match='end before'):
        wire.read_joint_command(data[:-12])  # the effort cut off


def test_big_endian_cdr_reads_the_same():
    def string(text: bytes, at: int) -> bytes:
        pad = -at % 4
        return b'\0' * pad + struct.pack('>I', len(text) + 1) + text + b'\0'

    body = struct.pack('>iI', 5, 6)
    body += string(b'base', len(body))
    body += b'\0' * (-len(body) % 4) + struct.pack('>I', 2)
    body += string(b'left', len(body))
    body += string(b'right', len(body))
    body += b'\0' * (-len(body) % 4) + struct.pack('>I', 0)  # no positions
    body += struct.pack('>I', 2)
    body += b'\0' * (-len(body) % 8) + struct.pack('>2d', 1.5, -2.5)
    body += struct.pack('>I', 0)  # no efforts
    command = wire.read_joint_command(b'\x00\x00\x00\x00' + body)
    assert command == wire.JointCommand(('left', 'right'), (1.5, -2.5))


@pytest.mark.parametrize('data, reason', [
    (b'', 'no CDR header'),
    (b'\x00\x01\x00', 'no CDR header'),
    (b'\x00\x01\x00\x00', 'end before'),
    (b'\x00\x05\x00\x00' + b'\x00' * 40, 'not CDR'),
    (b'\x00\x01\x00\x00' + b'\x00' * 8 + struct.pack('<I', 0) + b'\x00' * 20,
     'a string of 0 bytes'),
    (b'\x00\x01\x00\x00' + b'\x00' * 8 + struct.pack('<I', 2) + b'ab' + b'\x00' * 20,
     'without its terminating NUL'),
    (b'\x00\x01\x00\x00' + b'\x00' * 8 + struct.pack('<I', 1) + b'\x00\x00\x00\x00' +
     struct.pack('<I', 0xFFFFFFFF) + b'\x00' * 8, 'names in'),
    (b'\x00\x01\x00\x00' + b'\x00' * 8 + struct.pack('<I', 1) + b'\x00\x00\x00\x00' +
     struct.pack('<II', 1, 2) + b'\xff\x00' + b'\x00' * 30, 'not UTF-8'),
])
def test_bytes_that_are_no_joint_state_say_why(data, reason):
    with pytest.raises(wire.MalformedCommand, match=reason):
        wire.read_joint_command(data)


def test_another_encapsulation_goes_to_the_deserializer():
    seen = []

    def deserialize(data):
        seen.append(data)
        return JointState(name=['a'], velocity=[4.0])

    data = b'\x00\x07\x00\x00' + b'\x00' * 12  # XCDR2 little-endian
    assert wire.read_joint_command(data, deserialize) == wire.JointCommand(('a',), (4.0,))
    assert seen == [data]

    def broken(data):
        raise ValueError('cannot')

    with pytest.raises(wire.MalformedCommand, match='encapsulation 0007: cannot'):
        wire.read_joint_command(data, broken)
