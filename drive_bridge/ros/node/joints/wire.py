"""
``sensor_msgs/JointState`` commands read from their serialized form: names and velocities.

rclpy turns every message it takes into Python objects through the message class's own
constructor and property setters: for a JointState of 8 joints a header, 8 strings and three
arrays, most of the cost of a ``~/joint_commands`` message on the commands thread. The
subscription takes the message serialized instead (``raw=True``), and
:func:`read_joint_command` reads what the commands use, the names and the velocities, from
the bytes (position, effort and the header are skipped; they are ignored anyway).

The bytes are CDR as DDS carries them (OMG DDS-XTypes 1.3, section 7.4.3, "XCDR1": the
plain CDR that ROS 2's RMWs write): a 4-byte encapsulation header (``00 01``: little-endian,
``00 00``: big-endian), then the fields in order, each aligned to its size counted from the
end of that header (a string: its length with the terminating NUL as a uint32, then the
bytes; a sequence: its length as a uint32, then the elements). Any other encapsulation
(XCDR2, parameter lists) is read by rclpy's own deserializer, so nothing a DDS delivers is
refused for its encoding. Bytes that do not hold a whole JointState raise
:class:`MalformedCommand` with the reason: the message is counted and ignored, nothing sent.
"""

from dataclasses import dataclass
import struct
from typing import Callable, Optional, Sequence, Tuple

from drive_bridge.ros.node.cdr import ENCAPSULATIONS, HEADER_BYTES, MalformedMessage

MAX_NAME_BYTES = 4096  # a longer joint name is not a joint name (and not a 1 GB allocation)


class MalformedCommand(MalformedMessage):
    """The bytes are not a whole serialized JointState."""


@dataclass(frozen=True)
class JointCommand:
    """What a ``~/joint_commands`` message carries for the commands: names and velocities."""

    name: Tuple[str, ...]
    velocity: Tuple[float, ...]


class _Reader:
    """Reads CDR fields in order from one serialized message."""

    def __init__(self, data: bytes, order: str):
        self._data = data
        self._order = order
        self._at = HEADER_BYTES

    def _align(self, size: int) -> None:
        self._at += -(self._at - HEADER_BYTES) % size

    def _take(self, count: int) -> int:
        start = self._at
        if count < 0 or start + count > len(self._data):
            raise MalformedCommand(f'{len(self._data)} bytes end before field at byte {start} '
                                   f'({count} bytes)')
        self._at = start + count
        return start

    def uint32(self) -> int:
        self._align(4)
        return struct.unpack_from(self._order + 'I', self._data, self._take(4))[0]

    def string(self) -> str:
        length = self.uint32()  # with the terminating NUL
        if not 1 <= length <= MAX_NAME_BYTES:
            raise MalformedCommand(f'a string of {length} bytes')
        raw = self._data[self._take(length):self._at]
        if raw[-1:] != b'\x00':
            raise MalformedCommand('a string without its terminating NUL')
        try:
            return raw[:-1].decode('utf-8')
        except UnicodeDecodeError as error:
            raise MalformedCommand(f'a name that is not UTF-8 ({error})') from None

    def doubles(self) -> Tuple[float, ...]:
        count = self.uint32()
        if not count:
            return ()
        self._align(8)
        start = self._take(8 * count)
        return struct.unpack_from(f'{self._order}{count}d', self._data, start)

    def skip_doubles(self) -> None:
        count = self.uint32()
        if count:
            self._align(8)
            self._take(8 * count)

    def strings(self) -> Tuple[str, ...]:
        count = self.uint32()
        if count > len(self._data):  # each string takes 5 bytes at least
            raise MalformedCommand(f'{count} names in {len(self._data)} bytes')
        return tuple(self.string() for _ in range(count))


def read_cdr(data: bytes, order: str) -> JointCommand:
    """Read names and velocities from XCDR1 bytes of byte ``order`` ('<' or '>')."""
    reader = _Reader(data, order)
    reader.uint32()  # header.stamp.sec (int32: the bits are all that is skipped)
    reader.uint32()  # header.stamp.nanosec
    reader.string()  # header.frame_id
    names = reader.strings()
    reader.skip_doubles()  # position
    velocities = reader.doubles()
    reader.skip_doubles()  # effort: read, so that a message cut short is malformed
    return JointCommand(names, velocities)


def read_joint_command(data: bytes,
                       deserialize: Optional[Callable[[bytes], object]] = None) -> JointCommand:
    """
    Return the names and velocities of a serialized JointState; raise MalformedCommand.

    ``deserialize`` takes the bytes of an encapsulation other than XCDR1 (rclpy's
    ``deserialize_message`` for JointState); without it such bytes are malformed.
    """
    data = bytes(data)
    if len(data) < HEADER_BYTES:
        raise MalformedCommand(f'{len(data)} bytes, no CDR header')
    order = ENCAPSULATIONS.get(data[:2])
    if order is not None:
        return read_cdr(data, order)
    if deserialize is None:
        raise MalformedCommand(f'encapsulation {data[:2].hex()} is not CDR')
    try:
        message = deserialize(data)
    except Exception as error:  # noqa: B902 - whatever the deserializer raises: malformed
        raise MalformedCommand(f'encapsulation {data[:2].hex()}: {error}') from None
    return JointCommand(tuple(message.name), tuple(message.velocity))


def joint_command_of(names: Sequence[str], velocities: Sequence[float]) -> JointCommand:
    """Return a JointCommand of plain values (tests, and messages taken as objects)."""
    return JointCommand(tuple(names), tuple(float(value) for value in velocities))
