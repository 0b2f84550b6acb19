"""
Small ROS messages read from their serialized form: ``std_msgs/Float32``.

rclpy drops bytes that its typed subscription cannot deserialize before any callback runs:
whoever publishes them is told nothing, and neither is the log. A subscription that takes
the message serialized (``raw=True``) reads the bytes here and says why it refuses them.

The bytes are CDR as DDS carries them (OMG DDS-XTypes 1.3, section 7.4.3, "XCDR1": the
plain CDR that ROS 2's RMWs write): a 4-byte encapsulation header (``00 01``: little-endian,
``00 00``: big-endian), then the fields in order, each aligned to its size counted from the
end of that header; trailing bytes are padding. Any other encapsulation (XCDR2, parameter
lists) goes to rclpy's own deserializer, which decides as it does for a typed subscription.
:mod:`drive_bridge.ros.node.joints.wire` reads ``sensor_msgs/JointState`` the same way.
"""

import struct
from typing import Callable, Optional

ENCAPSULATIONS = {b'\x00\x01': '<', b'\x00\x00': '>'}  # CDR little- and big-endian
HEADER_BYTES = 4


class MalformedMessage(ValueError):
    """The bytes are not a whole serialized message of the type the topic carries."""


def read_float32(data: bytes,
                 deserialize: Optional[Callable[[bytes], object]] = None) -> float:
    """
    Return the ``data`` field of a serialized ``std_msgs/Float32``; raise MalformedMessage.

    ``deserialize`` takes the bytes of an encapsulation other than XCDR1 (rclpy's
    ``deserialize_message`` for Float32); without it such bytes are malformed. The low two
    bits of the header's options count the padding at the end (XTypes 1.3, 7.6.3.1.2): a
    writer's Float32 has none, and bytes whose padding leaves no whole float are malformed.
    """
    data = bytes(data)
    if len(data) < HEADER_BYTES:
        raise MalformedMessage(f'{_bytes(len(data))}, no CDR header')
    order = ENCAPSULATIONS.get(data[:2])
    if order is not None:
        body = len(data) - HEADER_BYTES - (data[3] & 3)
        if body < 4:
            raise MalformedMessage(f'{_bytes(len(data))} end before the whole float, bytes '
                                   f'{HEADER_BYTES}-{HEADER_BYTES + 3}')
        return struct.unpack_from(order + 'f', data, HEADER_BYTES)[0]
    if deserialize is None:
        raise MalformedMessage(f'encapsulation {data[:2].hex()} is not CDR')
    try:
        message = deserialize(data)
    except Exception as error:  # noqa: B902 - whatever the deserializer raises: malformed
        reason = str(error).split(', at ')[0]  # without the C++ source file rcl names
        raise MalformedMessage(f'encapsulation {data[:2].hex()}: {reason}') from None
    return float(message.data)


def _bytes(count: int) -> str:
    return '1 byte' if count == 1 else f'{count} bytes'
