"""Word and bit helpers for 16-bit registers."""


def bits(word: int, low: int, high: int) -> int:
    """Return bits ``low``..``high`` (inclusive) of ``word``, shifted down."""
    width = high - low + 1
    return (word >> low) & ((1 << width) - 1)


def bit(word: int, index: int) -> bool:
    """Return whether bit ``index`` of ``word`` is set."""
    return bool((word >> index) & 1)


def to_signed16(word: int) -> int:
    """Interpret a 16-bit word as two's complement."""
    word &= 0xFFFF
    return word - 0x10000 if word & 0x8000 else word


def from_signed16(value: int) -> int:
    """Encode a signed integer in [-32768, 32767] as a 16-bit two's complement word."""
    if not -0x8000 <= value <= 0x7FFF:
        raise ValueError(f'{value} does not fit in a signed 16-bit word')
    return value & 0xFFFF


def join_u32(high_word: int, low_word: int) -> int:
    """Join two registers, high word first, into an unsigned 32-bit value."""
    return ((high_word & 0xFFFF) << 16) | (low_word & 0xFFFF)


def split_u32(value: int) -> tuple:
    """Split an unsigned 32-bit value into (high word, low word)."""
    if not 0 <= value <= 0xFFFFFFFF:
        raise ValueError(f'{value} does not fit in an unsigned 32-bit value')
    return (value >> 16) & 0xFFFF, value & 0xFFFF


def to_signed32(value: int) -> int:
    """Interpret an unsigned 32-bit value as two's complement."""
    value &= 0xFFFFFFFF
    return value - 0x100000000 if value & 0x80000000 else value


def words_to_coils(words: list) -> tuple:
    """
    Spread 16-bit words over coils, 16 a word, least significant bit first.

    Coil 1 is bit 0 of the first word, so a function 0F request carries each word low
    byte first, as the VLT option card manual's frames show (0x047C -> ``7C 04``).
    """
    return tuple(bool((word >> index) & 1) for word in words for index in range(16))


def coils_to_words(coils: list) -> list:
    """Join coils (16 a word, least significant bit first) back into 16-bit words."""
    if len(coils) % 16:
        raise ValueError(f'{len(coils)} coils are not a whole number of 16-bit words')
    return [sum(1 << index for index in range(16) if coils[offset + index])
            for offset in range(0, len(coils), 16)]


def registers_to_text(registers: list) -> str:
    """Decode a text parameter: two characters a register, high byte first, trailing spaces cut."""
    raw = b''.join((register & 0xFFFF).to_bytes(2, 'big') for register in registers)
    return raw.split(b'\x00', 1)[0].decode('latin-1').rstrip(' ')


def text_to_registers(text: str, characters: int) -> list:
    """Encode ``text`` space-filled to ``characters`` (even) as registers, high byte first."""
    raw = text.encode('latin-1')
    if len(raw) > characters:
        raise ValueError(f'text {text!r} is longer than {characters} characters')
    raw = raw.ljust(characters + characters % 2, b' ')
    return [int.from_bytes(raw[index:index + 2], 'big') for index in range(0, len(raw), 2)]


def bytes_to_registers(data: bytes, byte_order: str = 'big') -> list:
    """
    Pack bytes into 16-bit registers, two a register, an odd last byte filled with 0.

    ``byte_order`` 'big': the first byte is the high byte (how most Profibus-to-Modbus
    gateways map a process image); 'little': the first byte is the low byte.
    """
    padded = bytes(data) + b'\x00' * (len(data) % 2)
    order = 'big' if byte_order == 'big' else 'little'
    return [int.from_bytes(padded[index:index + 2], order)
            for index in range(0, len(padded), 2)]


def registers_to_bytes(registers: list, count: int, byte_order: str = 'big') -> bytes:
    """Unpack ``count`` bytes from 16-bit registers (see :func:`bytes_to_registers`)."""
    order = 'big' if byte_order == 'big' else 'little'
    data = b''.join((register & 0xFFFF).to_bytes(2, order) for register in registers)
    if len(data) < count:
        raise ValueError(f'{len(registers)} registers hold {len(data)} bytes, not {count}')
    return data[:count]
