"""
The Danfoss FC protocol: telegrams, BCC, addresses, the parameter channel. Pure, no I/O.

The drives' own RS-485 protocol (VLT 5000/6000 with par. 500 = FC protocol, FC 51 and the
other FC series with 8-30 = FC); no option card needed. Each fact below is marked
**confirmed** (a Danfoss document says so) or **inferred** (our reading: the code is
tolerant of it or lets it be set).

Telegram (**confirmed**, FC 300 / FC 102 / VLT 5000 / VLT 2800 Design Guides "Telegram
Structure"): ``STX(02h) LGE ADR data BCC``. LGE counts the data bytes plus ADR and BCC, so a
telegram is LGE + 2 bytes: LGE 6 = process block ``PCD1 PCD2``; LGE 14 = parameter block
``PKE IND PWEhigh PWElow PCD1 PCD2``; LGE 10 + n = text block, the n text characters in place
of PWE (manual 003 "Text Blocks": "PWE is replaced with the text block"; VLT 5000 Design
Guide "Additional Text": reply ``02 11 01 F0 01 00 01`` + "ENGLISH" + PCD, LGE 11h for 7
characters). Words are big-endian. BCC is the XOR of every byte from STX up to BCC
(confirmed, worked example ``02 D6 -> D4``). A character is 11 bits: start, 8 data, even
parity, stop (confirmed; par. 8-33 "Even parity, 1 stop bit (default)").

Only three telegram types exist (**confirmed**, "The Data Field"); PPO types are Profibus's,
not the FC protocol's. A text block of exactly 4 characters has LGE 14 and is
indistinguishable from a parameter block: :class:`FcTelegram` keeps it as PWE and
:attr:`FcTelegram.text_value` gives it back as text (**inferred**, the only consistent reading).

Address byte ADR (**confirmed**, every Design Guide): format 1-31 = bit 7 clear, bit 5 set
for broadcast (bits 0-4 then unused), bits 0-4 the address; format 1-126 = bit 7 set, bits
0-6 the address, 0 = broadcast. The slave returns ADR unchanged. Nobody answers a broadcast,
and only a slave that received a faultless telegram for itself answers (**confirmed**, VLT
2800/8000 "Telegram Traffic"). The FC 51/101/360 guides list only format 1-126, so that is the
default here (**inferred**); the VLT 5000 examples use 1-31.

Parameter channel (**confirmed**): PKE = AK << 12 | PNU. AK requests 0 none, 1 read, 2 write
word RAM, 3 write double word RAM, 13 write double word RAM + EEPROM, 14 write word RAM +
EEPROM, 15 read/write text; replies 0 none, 1 word, 2 double word, 7 cannot be performed
(error code in PWElow), 15 text. PNU: bits 0-11 on the FC series (FC 51 Design Guide MG02K202
8.4.8; FC 300 Design Guide: "4-14 is 19E in hexadecimal", so 16-14 is PNU 1614 = 64Eh, which
fits), bits 0-10 on the VLT 5000/6000 (bit 11 "not in use", VLT 6000 Design Guide; it is the
SPM bit of the Profibus PCV): a reply differing only in bit 11 is accepted (**inferred**).
IND: the low byte is the array index; its high byte 04h reads and 05h writes a text with
AK 15 (**confirmed**, FC 102/202 Design Guides "Text via PWE block", manual 003 "IND").

Error codes of AK 7 replies: :data:`ERROR_CODES` (sources there). The reply to a write is
taken to be AK 1/2 with the value (**inferred**: the guides' reply figures are not in their
text); the reply to a text write is any AK 15 reply (**inferred**). The decoder has
pymodbus's "need more bytes" contract; :class:`ReplyFramer` is the master's framer of replies.

Worked vectors (VLT 5000 Design Guide MG.52.B2.02, FC 300 Design Guide MG.33.B6.22): start
at 50 % ``02 06 04 04 7C 20 00 58`` -> ``02 06 04 06 07 00 00 01``; read par. 520 ``02 0E 01
12 08 00 .. 00 17`` -> ``02 0E 01 22 08 00 00 00 00 02 0C 06 07 00 00 28`` (5.24 A, status
0607h). The FC 300 guide's 16-14 version prints PKE ``06 4E`` (AK 0, BCC 45h/4Ah): its AK
nibble was dropped; AK 1/2 gives BCC 55h/6Ah (a test checks both).
"""

from dataclasses import dataclass
import struct
from typing import Dict, Optional, Tuple

from drive_bridge.errors import ProtocolError
from drive_bridge.protocol import rtu
from drive_bridge.protocol.framing import Cut, Frame
from drive_bridge.protocol.requests import Request

STX = 0x02
CONTROL_DATA_VALID = 1 << 10  # control word bit 10: 0 = the drive ignores the control word
LGE_PROCESS = 6  # ADR + PCD1 PCD2 + BCC
LGE_PARAMETER = 14  # ADR + PKE IND PWEhigh PWElow PCD1 PCD2 + BCC
LGE_TEXT_FIXED = 10  # ADR + PKE IND + PCD1 PCD2 + BCC; + n text characters
MAX_LGE = 0xFF
MAX_TEXT_BYTES = MAX_LGE - LGE_TEXT_FIXED
MIN_TELEGRAM_BYTES = LGE_PROCESS + 2  # STX LGE + LGE bytes

ADDRESS_FORMAT_31 = '1-31'
ADDRESS_FORMAT_126 = '1-126'
ADDRESS_FORMATS = (ADDRESS_FORMAT_31, ADDRESS_FORMAT_126)
DEFAULT_ADDRESS_FORMAT = ADDRESS_FORMAT_126
BROADCAST = 0  # the address that means "every slave, nobody answers"
_FORMAT_126_BIT = 0x80
_BROADCAST_31_BIT = 0x20

# AK, the parameter command (master -> slave).
AK_NONE = 0
AK_READ = 1
AK_WRITE_WORD = 2
AK_WRITE_DOUBLE = 3
AK_WRITE_DOUBLE_EEPROM = 13
AK_WRITE_WORD_EEPROM = 14
AK_TEXT = 15
# AK, the reply (slave -> master).
AK_REPLY_NONE = 0
AK_REPLY_WORD = 1
AK_REPLY_DOUBLE = 2
AK_REPLY_ERROR = 7
AK_REPLY_TEXT = 15
REQUEST_NAMES: Dict[int, str] = {
    AK_NONE: 'no command', AK_READ: 'read', AK_WRITE_WORD: 'write word (RAM)',
    AK_WRITE_DOUBLE: 'write double word (RAM)',
    AK_WRITE_DOUBLE_EEPROM: 'write double word (RAM and EEPROM)',
    AK_WRITE_WORD_EEPROM: 'write word (RAM and EEPROM)', AK_TEXT: 'read/write text',
}
REPLY_NAMES: Dict[int, str] = {
    AK_REPLY_NONE: 'no response', AK_REPLY_WORD: 'value (word)',
    AK_REPLY_DOUBLE: 'value (double word)', AK_REPLY_ERROR: 'cannot be performed',
    AK_REPLY_TEXT: 'text',
}
WRITE_AKS = (AK_WRITE_WORD, AK_WRITE_DOUBLE, AK_WRITE_DOUBLE_EEPROM, AK_WRITE_WORD_EEPROM)
DOUBLE_WORD_AKS = (AK_WRITE_DOUBLE, AK_WRITE_DOUBLE_EEPROM)
EEPROM_AKS = (AK_WRITE_DOUBLE_EEPROM, AK_WRITE_WORD_EEPROM)
# What a reply to each request may carry besides AK 7 (reply to a write: inferred).
_REPLIES_TO: Dict[int, Tuple[int, ...]] = {
    AK_NONE: (AK_REPLY_NONE,), AK_READ: (AK_REPLY_WORD, AK_REPLY_DOUBLE),
    AK_TEXT: (AK_REPLY_TEXT,),
    **{ak: (AK_REPLY_WORD, AK_REPLY_DOUBLE) for ak in WRITE_AKS},
}

PNU_MASK = 0x0FFF  # bits 0-11 (FC series); the VLT 5000/6000 use bits 0-10
VLT_UNUSED_PNU_BIT = 0x0800
TEXT_MODE_MASK = 0xFF00
TEXT_READ_INDEX = 0x0400  # IND high byte 04h: read text (AK 15)
TEXT_WRITE_INDEX = 0x0500  # IND high byte 05h: write text (AK 15)

# AK 7 error codes (PWElow), decimal. 0-5, 17, 130, 131: VLT 6000 HVAC Design Guide
# MG.60.B1.02, FC 300 Design Guide MG.33.B3.22 (the FC 100/FC 322 guides print the same codes
# in hex: 11h, 82h, 83h); 9, 11, 15, 18, 132, 252-255: FC 101 Design Guide MG18C522 table 7.7
# and FC 51 Design Guide MG02K202 table 8.7; 23: FCP 106 Design Guide table 3.7.
ERROR_CODES: Dict[int, str] = {
    0: 'the parameter number does not exist',
    1: 'the parameter cannot be changed (no write access)',
    2: 'the value is outside the parameter limits',
    3: 'the sub-index (IND) does not exist',
    4: 'the parameter is not an array',
    5: 'the data type does not match the parameter (word/double word/text)',
    9: 'the description element is not available',
    11: 'no parameter write access',
    15: 'no text available',
    17: 'not possible while running: stop the motor first',
    18: 'other error',
    23: 'the parameter database is busy',
    130: 'no bus access to this parameter',
    131: 'write to the factory set-up is not possible',
    132: 'no LCP access',
    252: 'unknown viewer',
    253: 'request not supported',
    254: 'unknown attribute',
    255: 'no error',
}
NO_SUCH_PARAMETER, NO_WRITE_ACCESS, OUT_OF_LIMITS, NO_SUCH_INDEX = 0, 1, 2, 3
WRONG_DATA_TYPE, NOT_WHILE_RUNNING, REQUEST_NOT_SUPPORTED = 5, 17, 253

# Line (confirmed): 8 data bits, even parity, 1 stop bit by default, 11 bits a character;
# VLT 5000 par. 501 and FC 8-32 default 9600 baud. Timing (confirmed, VLT 5000 Crane and
# VLT 8000 AQUA instructions): at most 2 characters between the bytes of a telegram, a
# telegram complete within 1.5 times its nominal time, at least 2 characters before the
# reply and before the next telegram, a reply within 20 ms (VLT 5000) or 50 ms (VLT 2800,
# VLT 8000): the 50 ms is used as the slowest documented reply.
DEFAULT_BAUDRATE = 9600
DEFAULT_PARITY = 'E'
DEFAULT_STOPBITS = 1
GAP_CHARACTERS = 2
TELEGRAM_TIME_FACTOR = 1.5
MAX_REPLY_DELAY_S = 0.050

# Decoder error kinds.
ERROR_BCC, ERROR_BAD_STX, ERROR_BAD_LENGTH, ERROR_WRONG_ADDRESS = (
    'bcc', 'bad_stx', 'bad_length', 'wrong_address')


def bcc(data: bytes) -> int:
    """Return the BCC of ``data``: the XOR of every byte (STX included)."""
    value = 0
    for byte in data:
        value ^= byte
    return value


# -- addresses --------------------------------------------------------------------------
@dataclass(frozen=True)
class FcAddress:
    """A decoded ADR byte: the address (0 = broadcast), its format, and broadcast."""

    address: int
    address_format: str
    broadcast: bool


def encode_address(address: int, address_format: str = DEFAULT_ADDRESS_FORMAT) -> int:
    """Return the ADR byte of ``address`` (0 = broadcast); raise ProtocolError."""
    if address_format not in ADDRESS_FORMATS:
        raise ProtocolError(f'address format {address_format!r} is not one of '
                            f'{", ".join(ADDRESS_FORMATS)}')
    top = 31 if address_format == ADDRESS_FORMAT_31 else 126
    if not isinstance(address, int) or not 0 <= address <= top:
        raise ProtocolError(f'FC protocol address {address!r} is outside 1-{top} '
                            f'(format {address_format}; 0 = broadcast)')
    if address_format == ADDRESS_FORMAT_31:
        return _BROADCAST_31_BIT if address == BROADCAST else address
    return _FORMAT_126_BIT | address


def decode_address(adr: int) -> FcAddress:
    """Return what an ADR byte says (never raises for a byte 0-255)."""
    if adr & _FORMAT_126_BIT:
        address = adr & 0x7F
        return FcAddress(address, ADDRESS_FORMAT_126, address == BROADCAST)
    if adr & _BROADCAST_31_BIT:
        return FcAddress(BROADCAST, ADDRESS_FORMAT_31, True)
    address = adr & 0x1F
    return FcAddress(address, ADDRESS_FORMAT_31, address == BROADCAST)


def make_pke(ak: int, pnu: int) -> int:
    """Return PKE = AK << 12 | PNU; raise ProtocolError for an AK or PNU out of range."""
    if not 0 <= ak <= 15:
        raise ProtocolError(f'AK {ak} is outside 0-15')
    if not 0 <= pnu <= PNU_MASK:
        raise ProtocolError(f'parameter number {pnu} does not fit the 12-bit PNU field '
                            '(0-4095; FC series: 16-14 is 1614)')
    return ak << 12 | pnu


# -- telegrams --------------------------------------------------------------------------
@dataclass(frozen=True)
class FcTelegram:
    """
    One FC-protocol telegram, either direction.

    ``pke`` None: process block only (LGE 6). Otherwise a parameter block with ``ind`` and
    ``pwe`` (PWEhigh << 16 | PWElow, LGE 14), or a text block when ``text`` is set (LGE
    10 + n). A 4-byte text is stored as ``pwe`` (it is a parameter block on the wire).
    """

    adr: int
    pcd1: int = 0
    pcd2: int = 0
    pke: Optional[int] = None
    ind: int = 0
    pwe: int = 0
    text: Optional[bytes] = None

    def __post_init__(self):
        _check_range('ADR', self.adr, 0xFF)
        for name in ('pcd1', 'pcd2', 'ind'):
            _check_range(name.upper(), getattr(self, name), 0xFFFF)
        _check_range('PWE', self.pwe, 0xFFFFFFFF)
        if self.pke is None:
            if self.ind or self.pwe or self.text is not None:
                raise ProtocolError('a process-only telegram (no PKE) carries no IND, PWE '
                                    'or text')
            return
        _check_range('PKE', self.pke, 0xFFFF)
        if self.text is None:
            return
        text = bytes(self.text)
        if len(text) > MAX_TEXT_BYTES:
            raise ProtocolError(f'text of {len(text)} bytes does not fit a telegram '
                                f'(at most {MAX_TEXT_BYTES})')
        if self.pwe:
            raise ProtocolError('a text block has no PWE')
        if len(text) == 4:  # on the wire a parameter block: keep the canonical form
            object.__setattr__(self, 'pwe', int.from_bytes(text, 'big'))
            text = None
        object.__setattr__(self, 'text', text)

    @property
    def lge(self) -> int:
        """Return LGE: the bytes after LGE (ADR, data, BCC)."""
        if self.pke is None:
            return LGE_PROCESS
        if self.text is not None:
            return LGE_TEXT_FIXED + len(self.text)
        return LGE_PARAMETER

    @property
    def ak(self) -> Optional[int]:
        """Return the command/reply code (PKE bits 12-15), None without a parameter channel."""
        return None if self.pke is None else self.pke >> 12

    @property
    def pnu(self) -> Optional[int]:
        """Return the parameter number (PKE bits 0-11), None without a parameter channel."""
        return None if self.pke is None else self.pke & PNU_MASK

    @property
    def address(self) -> FcAddress:
        """Return the decoded ADR byte."""
        return decode_address(self.adr)

    @property
    def is_error(self) -> bool:
        """Return whether this is an AK 7 reply: "command cannot be performed"."""
        return self.ak == AK_REPLY_ERROR

    @property
    def error_code(self) -> int:
        """Return the error code of an AK 7 reply (PWElow)."""
        return self.pwe & 0xFFFF

    @property
    def text_value(self) -> bytes:
        """Return the text bytes of a text block (a 4-character text from PWE)."""
        if self.text is not None:
            return self.text
        return self.pwe.to_bytes(4, 'big') if self.pke is not None else b''

    def encode(self) -> bytes:
        """Return the telegram's bytes, BCC included."""
        body = bytes([STX, self.lge, self.adr])
        if self.pke is not None:
            body += struct.pack('>HH', self.pke, self.ind)
            body += self.text if self.text is not None else struct.pack('>I', self.pwe)
        body += struct.pack('>HH', self.pcd1, self.pcd2)
        return body + bytes([bcc(body)])

    def describe(self) -> str:
        """Return the telegram in words, for logs and messages."""
        text = f'ADR {self.adr:02X}h PCD1 {self.pcd1:04X}h PCD2 {self.pcd2:04X}h'
        if self.pke is None:
            return text
        text += f' AK {self.ak} PNU {self.pnu} IND {self.ind:04X}h'
        if self.text is not None:
            return text + f' text {self.text!r}'
        return text + f' PWE {self.pwe:08X}h'


def _check_range(name: str, value, top: int) -> None:
    if not isinstance(value, int) or isinstance(value, bool) or not 0 <= value <= top:
        raise ProtocolError(f'{name} {value!r} is outside 0-{top:X}h')


# -- decoder ----------------------------------------------------------------------------
@dataclass(frozen=True)
class DecodeResult:
    """
    What the decoder made of the bytes so far.

    ``telegram``: a whole valid telegram, ``consumed`` bytes long. ``error``: a kind
    (``bcc``, ``bad_stx``, ``bad_length``, ``wrong_address``) with ``reason`` in words;
    ``consumed`` bytes are to be dropped. Neither: ``missing`` more bytes are needed (at
    least; read them, then ask again).
    """

    telegram: Optional[FcTelegram] = None
    consumed: int = 0
    missing: int = 0
    error: str = ''
    reason: str = ''


def valid_lge(lge: int) -> bool:
    """Return whether LGE can start a telegram: 6, 14, or 10 + n for a text."""
    return lge == LGE_PROCESS or lge >= LGE_TEXT_FIXED


def decode(buffer: bytes, address_byte: Optional[int] = None,
           max_lge: int = MAX_LGE) -> DecodeResult:
    """
    Decode one telegram from the start of ``buffer``; never raises.

    ``address_byte``: the ADR the telegram must carry (a master's expected reply), else any.
    ``max_lge``: a longer LGE is ``bad_length`` at once (a master knows whether it asked for
    a text). The BCC is checked before the address, so a corrupted ADR counts as ``bcc``.
    """
    data = bytes(buffer)
    if not data:
        return DecodeResult(missing=MIN_TELEGRAM_BYTES)
    if data[0] != STX:
        return _skip(data, ERROR_BAD_STX, f'telegram starts with {data[0]:02X}h, not STX 02h')
    if len(data) < 2:
        return DecodeResult(missing=MIN_TELEGRAM_BYTES - len(data))
    lge = data[1]
    if not valid_lge(lge) or lge > max_lge:
        return _skip(data, ERROR_BAD_LENGTH,
                     f'LGE {lge} is not 6, 14 or 10 + text length'
                     + (f' (at most {max_lge} here)' if lge > max_lge else ''))
    total = lge + 2
    if len(data) < total:
        return DecodeResult(missing=total - len(data))
    candidate = data[:total]
    if bcc(candidate) != 0:
        return DecodeResult(consumed=total, error=ERROR_BCC,
                            reason=f'BCC {candidate[-1]:02X}h, expected '
                                   f'{bcc(candidate[:-1]):02X}h')
    if address_byte is not None and candidate[2] != address_byte:
        return DecodeResult(consumed=total, error=ERROR_WRONG_ADDRESS,
                            reason=f'reply from ADR {candidate[2]:02X}h, expected '
                                   f'{address_byte:02X}h')
    return DecodeResult(telegram=_parse(candidate), consumed=total)


def _skip(data: bytes, error: str, reason: str) -> DecodeResult:
    """Drop up to the next STX (a slave resynchronising), or everything."""
    following = data.find(bytes([STX]), 1)
    return DecodeResult(consumed=following if following > 0 else len(data), error=error,
                        reason=reason)


def _parse(candidate: bytes) -> FcTelegram:
    adr = candidate[2]
    pcd1, pcd2 = struct.unpack('>HH', candidate[-5:-1])
    if candidate[1] == LGE_PROCESS:
        return FcTelegram(adr, pcd1, pcd2)
    pke, ind = struct.unpack('>HH', candidate[3:7])
    payload = candidate[7:-5]
    if len(payload) == 4:
        return FcTelegram(adr, pcd1, pcd2, pke, ind, int.from_bytes(payload, 'big'))
    return FcTelegram(adr, pcd1, pcd2, pke, ind, text=payload)


class ReplyFramer:
    """
    FC-protocol telegrams as a master receives them: the :class:`~.framing.Framer` of FC.

    ``STX LGE`` give the length (LGE + 2 bytes); a first byte that is not STX, or an LGE no
    telegram has, begins no frame. The BCC decides whether a whole telegram is valid; a
    corrupt one still names the address of its ADR byte.
    """

    max_bytes = MAX_LGE + 2
    header_bytes = 3  # STX, LGE and the ADR byte
    names_units = True

    @staticmethod
    def cut(buffer: bytes) -> Cut:
        """Return the telegram at the start of ``buffer``, or what it needs; never raise."""
        if not buffer:
            return Cut(needed=MIN_TELEGRAM_BYTES)
        if buffer[0] != STX:
            return Cut()
        if len(buffer) < 2:
            return Cut(needed=MIN_TELEGRAM_BYTES)
        if not valid_lge(buffer[1]):
            return Cut()
        total = buffer[1] + 2
        if len(buffer) < total:
            return Cut(needed=total)
        raw = bytes(buffer[:total])
        unit = decode_address(raw[2]).address
        if bcc(raw) != 0:
            return Cut(Frame(raw, unit, f'BCC {raw[-1]:02X}h, expected {bcc(raw[:-1]):02X}h',
                             'crc'))
        return Cut(Frame(raw, unit))


# -- the master's requests --------------------------------------------------------------
@dataclass(frozen=True)
class FcTelegramRequest(Request):
    """
    One FC-protocol transaction as the bus asks for it: the telegram without its address.

    The transport adds the address (``execute(unit, request)``) in its address format,
    unless ``address_format`` names one here. It ``writes`` when its control word is valid
    (bit 10 set: the drive obeys it) or its parameter channel writes; a telegram with a
    control word without bit 10 and a read changes nothing in the drive.
    """

    control_word: int = 0
    reference: int = 0
    pke: Optional[int] = None
    ind: int = 0
    pwe: int = 0
    text: Optional[bytes] = None
    address_format: Optional[str] = None

    def telegram(self, address: int,
                 address_format: str = DEFAULT_ADDRESS_FORMAT) -> FcTelegram:
        """Return the telegram to ``address``; raise ProtocolError for bad values."""
        adr = encode_address(address, self.address_format or address_format)
        return FcTelegram(adr, self.control_word, self.reference, self.pke, self.ind,
                          self.pwe, self.text)

    @property
    def ak(self) -> Optional[int]:
        """Return the request's AK, None for process data only."""
        return None if self.pke is None else self.pke >> 12

    @property
    def pnu(self) -> Optional[int]:
        """Return the request's parameter number, None for process data only."""
        return None if self.pke is None else self.pke & PNU_MASK

    @property
    def writes(self) -> bool:
        """Return whether the telegram may change the drive (valid control data, a write)."""
        if self.control_word & CONTROL_DATA_VALID:
            return True
        return self.ak in WRITE_AKS or (self.ak == AK_TEXT and
                                        self.ind & TEXT_MODE_MASK == TEXT_WRITE_INDEX)

    def describe(self) -> str:
        """Return the request in words."""
        parts = [f'control word 0x{self.control_word:04X}', f'reference 0x{self.reference:04X}']
        if self.pke is not None:
            parts.append(f'AK {self.ak} ({REQUEST_NAMES.get(self.ak, "?")}) par. {self.pnu}')
        return f'FC telegram ({", ".join(parts)})'

    @property
    def max_reply_lge(self) -> int:
        """Return the longest LGE a valid reply can have (text requests: any)."""
        if self.pke is None:
            return LGE_PROCESS
        return MAX_LGE if self.ak == AK_TEXT else LGE_PARAMETER


def process_request(control_word: int, reference: int) -> FcTelegramRequest:
    """Return a process-data-only request (LGE 6): control word and reference."""
    return FcTelegramRequest(control_word, reference)


def read_parameter_request(pnu: int, index: int = 0, control_word: int = 0,
                           reference: int = 0) -> FcTelegramRequest:
    """
    Return a parameter read (AK 1) of ``pnu`` at array ``index``.

    A control word without bit 10 (the default 0) is ignored by the drive: the option card
    manual (003) sends parameter accesses with the process data "deactivated".
    """
    _check_index(index)
    return FcTelegramRequest(control_word, reference, make_pke(AK_READ, pnu), index)


def write_parameter_request(pnu: int, value: int, double_word: bool = False,
                            eeprom: bool = False, index: int = 0, control_word: int = 0,
                            reference: int = 0) -> FcTelegramRequest:
    """Return a parameter write: AK 2/14 (word) or 3/13 (double word), RAM or RAM + EEPROM."""
    _check_index(index)
    if double_word:
        ak = AK_WRITE_DOUBLE_EEPROM if eeprom else AK_WRITE_DOUBLE
        low, high = -0x80000000, 0xFFFFFFFF
    else:
        ak = AK_WRITE_WORD_EEPROM if eeprom else AK_WRITE_WORD
        low, high = -0x8000, 0xFFFF
    if not isinstance(value, int) or isinstance(value, bool) or not low <= value <= high:
        raise ProtocolError(f'value {value!r} does not fit a '
                            f'{"double word" if double_word else "word"} ({low} to {high})')
    pwe = value & (0xFFFFFFFF if double_word else 0xFFFF)
    return FcTelegramRequest(control_word, reference, make_pke(ak, pnu), index, pwe)


def read_text_request(pnu: int, index: int = 0, control_word: int = 0,
                      reference: int = 0) -> FcTelegramRequest:
    """Return a text read: AK 15, IND high byte 04h, an empty PWE (LGE 14)."""
    _check_index(index)
    return FcTelegramRequest(control_word, reference, make_pke(AK_TEXT, pnu),
                             TEXT_READ_INDEX | index)


def write_text_request(pnu: int, text: str, index: int = 0, control_word: int = 0,
                       reference: int = 0) -> FcTelegramRequest:
    """Return a text write: AK 15, IND high byte 05h, the text (Latin-1) in place of PWE."""
    _check_index(index)
    try:
        raw = text.encode('latin-1')
    except (AttributeError, UnicodeEncodeError) as error:
        raise ProtocolError(f'text {text!r} is not Latin-1 text: {error}') from None
    if len(raw) > MAX_TEXT_BYTES:
        raise ProtocolError(f'text of {len(raw)} characters does not fit a telegram')
    return FcTelegramRequest(control_word, reference, make_pke(AK_TEXT, pnu),
                             TEXT_WRITE_INDEX | index, text=raw)


def _check_index(index: int) -> None:
    if not isinstance(index, int) or not 0 <= index <= 0xFF:
        raise ProtocolError(f'array index {index!r} is outside 0-255 (IND low byte)')


def reply_problem(request: FcTelegramRequest, reply: FcTelegram) -> str:
    """
    Return why ``reply`` cannot answer ``request`` ('' when it can; AK 7 can).

    The PNU must match; a difference in bit 11 alone is accepted (VLT 5000/6000: unused).
    """
    if request.pke is None:
        return '' if reply.pke is None else \
            f'parameter reply (AK {reply.ak}) to a process-data telegram'
    if reply.pke is None:
        return f'process-data reply to a parameter request (AK {request.ak})'
    if (reply.pnu ^ request.pnu) & ~VLT_UNUSED_PNU_BIT:
        return f'reply for parameter {reply.pnu}, asked for {request.pnu}'
    if reply.ak == AK_REPLY_ERROR or reply.ak in _REPLIES_TO.get(request.ak, ()):
        return ''
    return (f'reply AK {reply.ak} ({REPLY_NAMES.get(reply.ak, "unknown")}) to AK '
            f'{request.ak} ({REQUEST_NAMES.get(request.ak, "unknown")})')


def explain_error(code: int) -> str:
    """Return technician text for the error code of an AK 7 reply."""
    text = ERROR_CODES.get(code, 'error code not in the Danfoss tables')
    return f'{text}, FC protocol error {code}'


# -- the slave's replies (the simulator) ------------------------------------------------
def reply_to(request: FcTelegram, status_word: int, actual_value: int,
             ak: Optional[int] = None, pwe: int = 0,
             text: Optional[bytes] = None) -> FcTelegram:
    """
    Return the slave's reply: ADR unchanged, status word and main actual value in PCD.

    A process-only request gets a process-only reply; a parameter request gets ``ak`` with
    the request's PNU and IND, and ``pwe`` or ``text``.
    """
    if request.pke is None:
        return FcTelegram(request.adr, status_word, actual_value)
    return FcTelegram(request.adr, status_word, actual_value,
                      make_pke(ak if ak is not None else AK_REPLY_NONE, request.pnu),
                      request.ind, pwe, text)


def error_reply(request: FcTelegram, code: int, status_word: int,
                actual_value: int) -> FcTelegram:
    """Return an AK 7 reply with error ``code`` in PWElow."""
    return reply_to(request, status_word, actual_value, AK_REPLY_ERROR, code & 0xFFFF)


# -- timing -----------------------------------------------------------------------------
def character_time_s(baudrate: int = DEFAULT_BAUDRATE, parity: str = DEFAULT_PARITY,
                     stopbits: int = DEFAULT_STOPBITS) -> float:
    """Return the time of one character on the wire (11 bits at 8E1)."""
    return rtu.character_time_s(baudrate, parity, stopbits)


def telegram_time_s(length: int, baudrate: int = DEFAULT_BAUDRATE,
                    parity: str = DEFAULT_PARITY, stopbits: int = DEFAULT_STOPBITS) -> float:
    """Return the nominal wire time of a telegram of ``length`` bytes."""
    return length * character_time_s(baudrate, parity, stopbits)


def transaction_wire_time_s(request_bytes: int, reply_bytes: int,
                            baudrate: int = DEFAULT_BAUDRATE, parity: str = DEFAULT_PARITY,
                            stopbits: int = DEFAULT_STOPBITS) -> float:
    """Return the least time one exchange holds the line: both telegrams and two 2-char gaps."""
    characters = request_bytes + reply_bytes + 2 * GAP_CHARACTERS
    return characters * character_time_s(baudrate, parity, stopbits)


def reply_deadline_s(reply_bytes: int, baudrate: int = DEFAULT_BAUDRATE,
                     parity: str = DEFAULT_PARITY, stopbits: int = DEFAULT_STOPBITS) -> float:
    """Return the documented worst case from request end to reply end: delay + 1.5 x time."""
    return MAX_REPLY_DELAY_S + TELEGRAM_TIME_FACTOR * telegram_time_s(
        reply_bytes, baudrate, parity, stopbits)
