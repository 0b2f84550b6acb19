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
