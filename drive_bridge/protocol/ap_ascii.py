"""
AP ASCII, the MCD soft starters' own serial protocol: fragments, LRC, status and data digits.

Pure. Sources: MCD Modbus Module manual ``000_b701c31669ff8873.txt`` section 10 (fragments,
commands B10-B18, requests C18/C22/D10/D12, LRC), its second extraction
``001_9e78dc5acbafdd65.txt`` (the worked LRC and how to verify one) and
``shared/research/protocols.md`` (exchange sequence, address LRC, status digit encodings).

Exchanges: command = master ``EOT nn lrc ENQ``, slave ``ACK``, master ``STX Bxx lrc ETX``,
slave ``ACK``; request = the same address fragment and ``ACK``, then ``STX Cxx|Dxx lrc ETX``,
slave ``STX dddd lrc ETX``. A slave answers a bad LRC with NAK and a refused command with BEL;
an unknown address never answers.
"""

from dataclasses import dataclass
from typing import Optional

from drive_bridge.protocol.commands import Command
from drive_bridge.protocol.framing import Cut, Frame

STX, ETX, EOT, ENQ, ACK, NAK, BEL = 0x02, 0x03, 0x04, 0x05, 0x06, 0x15, 0x07
SINGLE_BYTE_REPLIES = {ACK: 'ACK', NAK: 'NAK', BEL: 'BEL'}
FRAME_BYTES = 8  # STX d d d d lrc lrc ETX
ADDRESS_RANGE = (1, 99)  # two decimal digits
MIN_TIMEOUT_S = 0.25  # the MCD 3000 may take up to 250 ms to answer (protocols.md)

# Section 10.1: commands.
COMMANDS = {Command.START: 'B10', Command.STOP: 'B12', Command.RESET: 'B14',
            Command.QUICK_STOP: 'B16', Command.FORCED_COMMS_TRIP: 'B18'}
# Sections 10.2 and 10.3: requests and what their reply carries.
REQUESTS = {'trip_code': ('C18', 'status'), 'status': ('C22', 'status'),
            'motor_current': ('D10', 'data'), 'motor_temperature': ('D12', 'data')}


def lrc(data: bytes) -> int:
    """Return the LRC of ``data``: the two's complement of the byte sum, mod 256."""
    return (-sum(data)) & 0xFF


def lrc_ascii(data: bytes) -> bytes:
    """Return the LRC of ``data`` as two upper-case ASCII hex characters."""
    return b'%02X' % lrc(data)


def address_fragment(address: int, lrc_includes_eot: bool = True) -> bytes:
    """
    Return ``EOT nn lrc ENQ`` for ``address`` (01-99).

    Whether the address LRC covers EOT is not in the manual (protocols.md: inferred yes).
    """
    if not ADDRESS_RANGE[0] <= address <= ADDRESS_RANGE[1]:
        raise ValueError(f'AP ASCII address {address} is out of range 1-99')
    digits = b'%02d' % address
    checked = bytes([EOT]) + digits if lrc_includes_eot else digits
    return bytes([EOT]) + digits + lrc_ascii(checked) + bytes([ENQ])


def message_fragment(code: str) -> bytes:
    """Return ``STX ccc lrc ETX`` for a command or request code such as ``B10``."""
    body = bytes([STX]) + code.encode('ascii')
    return body + lrc_ascii(body) + bytes([ETX])


def data_fragment(digits: bytes) -> bytes:
    """Return ``STX dddd lrc ETX`` (a slave's reply) for four ASCII digits."""
    body = bytes([STX]) + digits
    return body + lrc_ascii(body) + bytes([ETX])


def lrc_matches(body: bytes, lrc_text: bytes) -> bool:
    """
    Verify a received LRC (001, "To verify a received message"): body plus LRC sums to 0.

    ``body`` starts with STX or EOT; the LRC is accepted computed with or without that
    first byte, since the manuals leave it open for addresses.
    """
    try:
        value = int(lrc_text.decode('ascii'), 16)
    except (UnicodeDecodeError, ValueError):
        return False
    if len(lrc_text) != 2:
        return False
    return (sum(body) + value) & 0xFF == 0 or (sum(body[1:]) + value) & 0xFF == 0


def encode_status(value: int, style: str = 'hex') -> bytes:
    """
    Return the four status digits of byte ``value``: ``00`` then the two nibbles.

    ``style`` 'hex' sends nibbles as ASCII hex (the manual's example: 1Fh -> ``001F``);
    'offset' as 30h + nibble (the manual's text: 1Fh -> ``001?``).
    """
    high, low = value >> 4 & 0x0F, value & 0x0F
    if style == 'offset':
        return bytes([0x30, 0x30, 0x30 + high, 0x30 + low])
    return b'00%X%X' % (high, low)


def decode_status(digits: bytes) -> int:
    """Return the status byte of four status digits, accepting both nibble encodings."""
    if len(digits) != 4 or digits[:2] != b'00':
        raise ValueError(f'status digits {digits!r} do not start with 00')
    return _nibble(digits[2]) << 4 | _nibble(digits[3])


def _nibble(char: int) -> int:
    if 0x30 <= char <= 0x3F:  # '0'-'9', and 30h + 10..15 (':' ... '?')
        return char - 0x30
    if 0x41 <= char <= 0x46:  # 'A'-'F'
        return char - 0x41 + 10
    raise ValueError(f'{bytes([char])!r} is not a status nibble')


def encode_data(value: int) -> bytes:
    """Return four decimal digits (0000-9999) for a data reply."""
    if not 0 <= value <= 9999:
        raise ValueError(f'data value {value} does not fit 4 decimal digits')
    return b'%04d' % value


def decode_data(digits: bytes) -> int:
    """Return the value of four decimal digits."""
    if len(digits) != 4 or not digits.isdigit():
        raise ValueError(f'data digits {digits!r} are not 4 decimal digits')
    return int(digits)


class ReplyFramer:
    """
    AP ASCII replies as a master receives them: the :class:`~.framing.Framer` of AP ASCII.

    ACK, NAK and BEL are frames of one byte, ``STX dddd lrc ETX`` one of eight; no reply names
    the slave that sent it (``unit`` None). Any other first byte begins no frame.
    """

    max_bytes = FRAME_BYTES
    header_bytes = FRAME_BYTES  # a reply names no unit: no cut one shows whose it is
    names_units = False

    @staticmethod
    def cut(buffer: bytes) -> Cut:
        """Return the reply at the start of ``buffer``, or what it needs; never raise."""
        if not buffer:
            return Cut(needed=1)
        if buffer[0] in SINGLE_BYTE_REPLIES:
            return Cut(Frame(bytes(buffer[:1])))
        if buffer[0] != STX:
            return Cut()
        if len(buffer) < FRAME_BYTES:
            return Cut(needed=FRAME_BYTES)
        raw = bytes(buffer[:FRAME_BYTES])
        if raw[-1] != ETX:
            return Cut(Frame(raw, None, 'reply is not STX dddd lrc ETX', 'bad_frame'))
        if not lrc_matches(raw[:5], raw[5:7]):
            return Cut(Frame(raw, None, 'LRC error in the reply', 'crc'))
        return Cut(Frame(raw))


def reply_kind(frame: Frame) -> str:
    """Return what a valid reply is: 'ACK', 'NAK', 'BEL' or 'frame' (four digits)."""
    return SINGLE_BYTE_REPLIES.get(frame.raw[0], 'frame')


@dataclass(frozen=True)
class Fragment:
    """One master fragment as a slave decodes it: 'address' (``address``) or 'message'."""

    kind: str
    address: Optional[int] = None
    code: str = ''
    lrc_ok: bool = True


def decode_fragment(buffer: bytes, lrc_includes_eot: Optional[bool] = None) -> tuple:
    """
    Decode one master fragment for a slave: return (Fragment or None, bytes consumed).

    (None, 0) means "need more bytes"; (None, n) drops n bytes of garbage.
    """
    if not buffer:
        return None, 0
    first = buffer[0]
    if first == EOT:
        if len(buffer) < 6:
            return None, 0
        digits, lrc_text, end = buffer[1:3], buffer[3:5], buffer[5]
        if end != ENQ or not digits.isdigit():
            return None, 1
        body = bytes([EOT]) + digits
        if lrc_includes_eot is None:
            ok = lrc_matches(body, lrc_text)
        else:
            ok = lrc_text == lrc_ascii(body if lrc_includes_eot else digits)
        return Fragment('address', address=int(digits), lrc_ok=ok), 6
    if first == STX:
        if len(buffer) < 7:
            return None, 0
        code, lrc_text, end = buffer[1:4], buffer[4:6], buffer[6]
        if end != ETX:
            return None, 1
        ok = lrc_text == lrc_ascii(bytes([STX]) + code)
        return Fragment('message', code=code.decode('latin-1'), lrc_ok=ok), 7
    return None, 1
