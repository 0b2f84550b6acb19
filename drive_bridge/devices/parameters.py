"""
Drive parameters over Modbus: data types, conversion indexes, register layout. No I/O.

FC series (manual 004, sections 5.4 and 6.2) and the VLT 5000/6000 option card (manual 003,
"Conversion Factor", "Memory Mapping") share the scheme: parameter N sits at frame address
10 * N - 1 (FC: N is the PNU without the dash, 16-14 -> 1614), 16-bit values in one
register, 32-bit values in two (high word first), text in up to 10 registers (20 characters),
and a conversion index that scales the whole number on the bus to the value shown.
"""

from dataclasses import dataclass
import math
from typing import Dict, Tuple, Union

from drive_bridge.errors import CommandRefused
from drive_bridge.protocol.words import (
    join_u32, registers_to_text, split_u32, text_to_registers, to_signed16, to_signed32)

# Manual 004 section 6.2.4 "Type": data type -> (registers, signed, minimum, maximum).
DATA_TYPES: Dict[str, Tuple[int, bool, int, int]] = {
    'int8': (1, True, -0x80, 0x7F),
    'int16': (1, True, -0x8000, 0x7FFF),
    'int32': (2, True, -0x80000000, 0x7FFFFFFF),
    'uint8': (1, False, 0, 0xFF),
    'uint16': (1, False, 0, 0xFFFF),
    'uint32': (2, False, 0, 0xFFFFFFFF),
}
TEXT = 'text'
MAX_TEXT_CHARACTERS = 20  # manual 004 section 5.4.4, manual 003 "Text Blocks"

# Manual 004 section 6.2.1, table 6.1, and shared/research/protocols.md: indexes 67, 74,
# 75 and 100 mean the raw value is already in display units on the FC series.
FC_CONVERSION_FACTORS: Dict[int, float] = {
    2: 100.0, 1: 10.0, 0: 1.0, -1: 0.1, -2: 0.01, -3: 0.001, -4: 0.0001, -5: 0.00001,
    67: 1.0, 74: 1.0, 75: 1.0, 100: 1.0,
}
# Manual 003, "Conversion Factor": the VLT 5000/6000 table (index 74 = 3.6).
VLT_CONVERSION_FACTORS: Dict[int, float] = {
    74: 3.6, 2: 100.0, 1: 10.0, 0: 1.0, -1: 0.1, -2: 0.01, -3: 0.001, -4: 0.0001,
}

Value = Union[int, float, str]


@dataclass(frozen=True)
class ParameterSpec:
    """One drive parameter: number, name, type, conversion index and where it is from."""

    number: int
    name: str
    data_type: str
    conversion: int = 0
    source: str = ''
    characters: int = MAX_TEXT_CHARACTERS  # text parameters only

    def __post_init__(self):
        if self.data_type not in DATA_TYPES and self.data_type != TEXT:
            raise ValueError(f'unknown data type {self.data_type!r}')

    @property
    def address(self) -> int:
        """Return the frame address: 10 * number - 1."""
        return parameter_address(self.number)

    @property
    def registers(self) -> int:
        """Return how many registers the value takes."""
        if self.data_type == TEXT:
            return (self.characters + 1) // 2
        return DATA_TYPES[self.data_type][0]


def parameter_address(number: int) -> int:
    """Return the frame address of parameter ``number`` (10 * number - 1)."""
    address = 10 * number - 1
    if not 0 <= address <= 0xFFFF or number < 1:
        raise CommandRefused(f'parameter {number} has no Modbus register (10 * N - 1 must be '
                             'a register address 0-65535)')
    return address


def decode_value(spec: ParameterSpec, registers: list, factors: Dict[int, float]) -> Value:
    """Return the parameter's value in display units (text as a string)."""
    if spec.data_type == TEXT:
        return registers_to_text(registers)
    count, signed, _, _ = DATA_TYPES[spec.data_type]
    if len(registers) != count:
        raise ValueError(f'{spec.name}: expected {count} registers, got {len(registers)}')
    if count == 2:
        raw = join_u32(registers[0], registers[1])
        raw = to_signed32(raw) if signed else raw
    else:
        raw = to_signed16(registers[0]) if signed else registers[0] & 0xFFFF
    factor = conversion_factor(spec, factors)
    return raw if factor == 1.0 else raw * factor


def encode_value(spec: ParameterSpec, value: Value, factors: Dict[int, float]) -> list:
    """Return the registers that write ``value`` (display units); raise CommandRefused."""
    if spec.data_type == TEXT:
        if not isinstance(value, str):
            raise CommandRefused(f'{spec.name} is a text parameter: give a string')
        if len(value) > spec.characters:
            raise CommandRefused(f'{spec.name}: {value!r} is longer than {spec.characters} '
                                 'characters')
        try:  # as many registers as the text needs, an odd length filled with a space
            return text_to_registers(value, len(value) + len(value) % 2)
        except (ValueError, UnicodeEncodeError) as error:
            raise CommandRefused(f'{spec.name}: {error}') from None
    if isinstance(value, (str, bool)):
        raise CommandRefused(f'{spec.name} takes a number, not {value!r}')
    count, _, minimum, maximum = DATA_TYPES[spec.data_type]
    factor = conversion_factor(spec, factors)
    if not math.isfinite(float(value)):
        raise CommandRefused(f'{spec.name}: {value} is not a finite number')
    raw = round(float(value) / factor)
    if not math.isclose(raw * factor, float(value), rel_tol=1e-9, abs_tol=factor * 1e-6):
        raise CommandRefused(f'{spec.name}: {value} is not a multiple of {factor:g}')
    if not minimum <= raw <= maximum:
        raise CommandRefused(
            f'{spec.name}: {value} is out of range for {spec.data_type} with conversion '
            f'index {spec.conversion} ({minimum * factor:g} to {maximum * factor:g})')
    if count == 2:
        return list(split_u32(raw & 0xFFFFFFFF))
    return [raw & 0xFFFF]


def conversion_factor(spec: ParameterSpec, factors: Dict[int, float]) -> float:
    """Return the factor of the spec's conversion index, or raise for an unknown index."""
    try:
        return factors[spec.conversion]
    except KeyError:
        raise CommandRefused(f'{spec.name}: unknown conversion index {spec.conversion} '
                             f'(known: {", ".join(str(i) for i in sorted(factors))})') from None
