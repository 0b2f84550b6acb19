"""
Modbus RTU framing, pure: request/response PDUs, ADUs with CRC, and a request decoder.

The decoder follows the contract of pymodbus's framers: it is given the bytes received so
far and answers with a complete frame and how many bytes it used, with "need more bytes",
or with how many bytes to discard (a frame whose CRC is wrong). It never raises on input.
Function codes and exception codes: Modbus Application Protocol V1.1b3, section 6 and 7.
"""

from dataclasses import dataclass
import struct
from typing import Optional

from drive_bridge.protocol.crc import append_crc, crc_ok
from drive_bridge.protocol.framing import Cut, Frame

READ_COILS = 0x01
READ_HOLDING_REGISTERS = 0x03
READ_INPUT_REGISTERS = 0x04
WRITE_SINGLE_COIL = 0x05
WRITE_SINGLE_REGISTER = 0x06
DIAGNOSTICS = 0x08
GET_COMM_EVENT_COUNTER = 0x0B
WRITE_MULTIPLE_COILS = 0x0F
WRITE_MULTIPLE_REGISTERS = 0x10
REPORT_SERVER_ID = 0x11

# Requests whose length is fixed: unit + function + 4 data bytes + CRC.
_FIXED_LENGTH_FUNCTIONS = {
    READ_COILS, 0x02, READ_HOLDING_REGISTERS, READ_INPUT_REGISTERS,
    WRITE_SINGLE_COIL, WRITE_SINGLE_REGISTER, DIAGNOSTICS,
}
# Requests with only unit + function + CRC.
_EMPTY_FUNCTIONS = {GET_COMM_EVENT_COUNTER, 0x0C, REPORT_SERVER_ID}
# Requests with a byte count at offset 6: unit fc addr(2) qty(2) count(1) data crc(2).
_COUNTED_FUNCTIONS = {WRITE_MULTIPLE_COILS, WRITE_MULTIPLE_REGISTERS}

MAX_ADU_BYTES = 256
MAX_UNIT = 247  # slave addresses are 1-247; 0 is broadcast, which nobody answers


@dataclass(frozen=True)
class RtuFrame:
    """One RTU frame without its CRC: unit address, function code and data bytes."""

    unit: int
    function: int
    data: bytes

    def encode(self) -> bytes:
        """Return the frame's bytes with the CRC appended."""
        return append_crc(bytes([self.unit, self.function]) + self.data)


@dataclass(frozen=True)
class DecodeResult:
    """
    What the decoder made of a buffer.

    ``frame`` is set when a whole valid frame was found; ``consumed`` bytes of the buffer
    are used up (a frame, or garbage to drop); both unset/zero means "need more bytes".
    ``error`` names what was dropped.
    """

    frame: Optional[RtuFrame] = None
    consumed: int = 0
    error: str = ''


def expected_request_length(buffer: bytes) -> Optional[int]:
    """
    Return the length of the request starting at ``buffer[0]``, or None if unknown yet.

    Returns -1 for a function code whose request length cannot be known from its header.
    """
    if len(buffer) < 2:
        return None
    function = buffer[1]
    if function in _FIXED_LENGTH_FUNCTIONS:
        return 8
    if function in _EMPTY_FUNCTIONS:
        return 4
    if function in _COUNTED_FUNCTIONS:
        if len(buffer) < 7:
            return None
        return 9 + buffer[6]
    return -1


def decode_request(buffer: bytes, gap_elapsed: bool = False) -> DecodeResult:
    """
    Decode one request from the start of ``buffer``.

    ``gap_elapsed`` tells that the line has been silent for 3.5 characters since the last
    byte: then a frame of unknown function ends where the buffer ends, and an incomplete
    frame is garbage.
    """
    if not buffer:
        return DecodeResult()
    length = expected_request_length(buffer)
    if length is None or (length > 0 and len(buffer) < length):
        if gap_elapsed:
            return DecodeResult(consumed=len(buffer), error='truncated frame')
        return DecodeResult()
    if length == -1:
        if not gap_elapsed:
            return DecodeResult()
        length = len(buffer)
    if length > MAX_ADU_BYTES:
        return DecodeResult(consumed=len(buffer), error='frame too long')
    candidate = buffer[:length]
    if not crc_ok(candidate):
        consumed = len(buffer) if gap_elapsed else length
        return DecodeResult(consumed=consumed, error='CRC error')
    frame = RtuFrame(candidate[0], candidate[1], bytes(candidate[2:-2]))
    return DecodeResult(frame=frame, consumed=length)


# Responses whose length is fixed: unit + function + 4 data bytes (echo) + CRC.
_ECHO_RESPONSES = {WRITE_SINGLE_COIL, WRITE_SINGLE_REGISTER, WRITE_MULTIPLE_COILS,
                   WRITE_MULTIPLE_REGISTERS}
# Responses with a byte count at offset 2: unit fc count data crc(2).
_COUNTED_RESPONSES = {READ_COILS, 0x02, READ_HOLDING_REGISTERS, READ_INPUT_REGISTERS}
MIN_RESPONSE_BYTES = 5  # the shortest response: an exception (unit fc code crc crc)


def response_length(buffer: bytes) -> Optional[int]:
    """Return the length of the response at ``buffer[0]``, or None if not known yet."""
    if len(buffer) < 2:
        return None
    function = buffer[1]
    if function & 0x80:
        return 5
    if function in _ECHO_RESPONSES:
        return 8
    if function in _COUNTED_RESPONSES:
        return 5 + buffer[2] if len(buffer) >= 3 else None
    return None


class ReplyFramer:
    """
    Modbus RTU replies as a master receives them: the :class:`~.framing.Framer` of RTU.

    A reply's length follows from its first bytes: an exception is 5 bytes, the echo of a
    write 8, a read 5 + its byte count. A first byte that is no slave address (0 or above
    247) or a function code no reply carries begins no frame. The CRC decides whether a whole
    frame is valid; a corrupt one still names the unit of its first byte.
    """

    max_bytes = MAX_ADU_BYTES
    header_bytes = 2  # unit and function: what a cut answer must show to be its own
    names_units = True

    @staticmethod
    def cut(buffer: bytes) -> Cut:
        """Return the reply at the start of ``buffer``, or what it needs; never raise."""
        if not buffer:
            return Cut(needed=MIN_RESPONSE_BYTES)
        if not 1 <= buffer[0] <= MAX_UNIT:
            return Cut()
        length = response_length(buffer)
        if length is None:
            if len(buffer) >= 2 and not _known_reply_function(buffer[1]):
                return Cut()
            return Cut(needed=max(len(buffer) + 1, 3))
        if len(buffer) < length:
            return Cut(needed=length)
        raw = bytes(buffer[:length])
        if not crc_ok(raw):
            return Cut(Frame(raw, raw[0], 'CRC error', 'crc'))
        return Cut(Frame(raw, raw[0]))


def _known_reply_function(function: int) -> bool:
    """Return whether a reply can carry ``function`` (exceptions: any, bit 7 set)."""
    return bool(function & 0x80) or function in _ECHO_RESPONSES or function in _COUNTED_RESPONSES


def reply_frame(frame: Frame) -> RtuFrame:
    """Return a valid received frame as an RtuFrame (unit, function, data without CRC)."""
    raw = frame.raw
    return RtuFrame(raw[0], raw[1], bytes(raw[2:-2]))


def read_registers_request(unit: int, address: int, count: int) -> RtuFrame:
    """Return a function 03 request for ``count`` registers from frame address ``address``."""
    return RtuFrame(unit, READ_HOLDING_REGISTERS, struct.pack('>HH', address, count))


def write_register_request(unit: int, address: int, value: int) -> RtuFrame:
    """Return a function 06 request writing ``value`` at frame address ``address``."""
    return RtuFrame(unit, WRITE_SINGLE_REGISTER, struct.pack('>HH', address, value))


def write_coil_request(unit: int, address: int, value: bool) -> RtuFrame:
    """Return a function 05 request: FF00h for on, 0000h for off."""
    return RtuFrame(unit, WRITE_SINGLE_COIL, struct.pack('>HH', address,
                                                         0xFF00 if value else 0))


def read_coils_request(unit: int, address: int, count: int) -> RtuFrame:
    """Return a function 01 request for ``count`` coils from coil address ``address``."""
    return RtuFrame(unit, READ_COILS, struct.pack('>HH', address, count))


def pack_coils(coils: list) -> bytes:
    """Pack coils eight to a byte, the first coil in the lowest bit (Modbus 01/0F)."""
    return bytes(sum(1 << bit for bit, on in enumerate(coils[start:start + 8]) if on)
                 for start in range(0, len(coils), 8))


def write_coils_request(unit: int, address: int, coils: list) -> RtuFrame:
    """Return a function 0F request writing ``coils`` (bools) from coil address ``address``."""
    packed = pack_coils(coils)
    return RtuFrame(unit, WRITE_MULTIPLE_COILS,
                    struct.pack('>HHB', address, len(coils), len(packed)) + packed)


def write_registers_request(unit: int, address: int, values: list) -> RtuFrame:
    """Return a function 10 request writing ``values`` from frame address ``address``."""
    payload = b''.join(struct.pack('>H', value & 0xFFFF) for value in values)
    return RtuFrame(unit, WRITE_MULTIPLE_REGISTERS,
                    struct.pack('>HHB', address, len(values), len(payload)) + payload)


def registers_response(unit: int, function: int, values: list) -> RtuFrame:
    """Return a read-registers response carrying ``values``."""
    payload = b''.join(struct.pack('>H', value & 0xFFFF) for value in values)
    return RtuFrame(unit, function, bytes([len(payload)]) + payload)


def exception_response(unit: int, function: int, code: int) -> RtuFrame:
    """Return an exception response: function with bit 7 set, then the exception code."""
    return RtuFrame(unit, function | 0x80, bytes([code]))


def parse_address_count(data: bytes) -> tuple:
    """Return (address, count-or-value) from the first four data bytes of a request."""
    return struct.unpack('>HH', data[:4])


def character_bits(parity: str, stopbits: int) -> int:
    """Return bits per character on the wire: start + 8 data + parity + stop bits."""
    return 1 + 8 + (0 if parity == 'N' else 1) + stopbits


def character_time_s(baudrate: int, parity: str = 'E', stopbits: int = 1) -> float:
    """Return the time one character takes on the wire, in seconds."""
    return character_bits(parity, stopbits) / float(baudrate)


def frame_gap_s(baudrate: int, parity: str = 'E', stopbits: int = 1) -> float:
    """Return the 3.5-character silence that ends a frame (1.75 ms above 19200 baud)."""
    if baudrate > 19200:
        return 0.00175
    return 3.5 * character_time_s(baudrate, parity, stopbits)


def default_stopbits(parity: str) -> int:
    """Return the Modbus standard's stop bits: 2 with no parity, 1 with parity (11 bits)."""
    return 2 if parity == 'N' else 1
