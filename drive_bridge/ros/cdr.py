"""
Small ROS messages read from their serialized form: ``std_msgs/Float32``.

rclpy drops bytes that its typed subscription cannot deserialize before any callback runs:
whoever publishes them is told nothing, and neither is the log. A subscription that takes
the message serialized (``raw=True``) reads the bytes here and says why it refuses them.

The bytes are CDR as DDS carries them (OMG DDS-XTypes 1.3, section 7.4.3, "XCDR1": the
plain CDR that ROS 2's RMWs write): a 4-byte encapsulation header (``00 01``: little-endian,
``00 00``: big-endian), then the fields in order, each aligned to its size counted from the
end of that header; trailing bytes are padding. Any other encapsulation (XCDR2, parameter
lists) is read by rclpy's own deserializer, so nothing a DDS delivers is refused for its
encoding. :mod:`drive_bridge.ros.joints.wire` reads ``sensor_msgs/JointState`` the same way.
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
    ``deserialize_message`` for Float32); without it such bytes are malformed.
    """
    data = bytes(data)
    if len(data) < HEADER_BYTES:
        raise MalformedMessage(f'{len(data)} bytes, no CDR header')
    order = ENCAPSULATIONS.get(data[:2])
    if order is not None:
        if len(data) < HEADER_BYTES + 4:
            raise MalformedMessage(f'{len(data)} bytes end before the float at byte '
                                   f'{HEADER_BYTES} (4 bytes)')
        return struct.unpack_from(order + 'f', data, HEADER_BYTES)[0]
    if deserialize is None:
        raise MalformedMessage(f'encapsulation {data[:2].hex()} is not CDR')
    try:
        message = deserialize(data)
    except Exception as error:  # noqa: B902 - whatever the deserializer raises: malformed
        raise MalformedMessage(f'encapsulation {data[:2].hex()}: {error}') from None
    return float(message.data)
