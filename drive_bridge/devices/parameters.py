"""
Drive parameters over Modbus: data types, conversion indexes, register layout. No I/O.

FC series (manual 004, sections 5.4 and 6.2) and the VLT 5000/6000 option card (manual 003,
"Conversion Factor", "Memory Mapping") share the scheme: parameter N sits at frame address
10 * N - 1 (FC: N is the PNU without the dash, 16-14 -> 1614), 16-bit values in one
register, 32-bit values in two (high word first), text in up to 10 registers (20 characters),
and a conversion index that scales the whole number on the bus to the value shown.
"""

from dataclasses import dataclass, field, fields
import math
from types import MappingProxyType
from typing import Dict, Iterable, List, Mapping, Optional, Tuple, Union

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
    """
    One drive parameter: number, name, type, conversion index and where it is from.

    The fields after ``characters`` describe the parameter for commissioning (get, set,
    backup, restore); every one is optional so that a bare ``ParameterSpec(number, name,
    data_type, conversion)`` still works. Limits are in display units (after conversion).
    ``inferred`` names the fields that no source states (see the table modules).
    """

    number: int
    name: str
    data_type: str
    conversion: int = 0
    source: str = ''
    characters: int = MAX_TEXT_CHARACTERS  # text parameters only
    minimum: Optional[float] = None  # display units
    maximum: Optional[float] = None
    options: Optional[Mapping[int, str]] = field(default=None, hash=False)  # value -> name
    options_partial: bool = False  # True: the known options only, others may be valid
    unit: str = ''
    change_running: Optional[bool] = None  # may be changed while the motor runs (None: unknown)
    setting: Optional[bool] = None  # True: a setting (backed up); False: readout or process data
    default: Optional[Union[int, float, str]] = None
    elements: int = 0  # array parameters: how many indexes (0: not an array)
    label: str = ''  # the manual's own designation when it is not the number (FC: 16-14)
    inferred: Tuple[str, ...] = ()  # names of the fields no source states
    # A setting of the drive's own serial line (protocol, address, baud rate, parity), or one
    # that keeps the device on the network (MCD 3000 par. 20): backed up and compared on
    # restore, never written by it (that would cut the device off the line).
    serial_line: bool = False

    def __post_init__(self):
        if self.data_type not in DATA_TYPES and self.data_type != TEXT:
            raise ValueError(f'unknown data type {self.data_type!r}')
        if self.options is not None:
            object.__setattr__(self, 'options', MappingProxyType(dict(self.options)))
        if (self.minimum is not None and self.maximum is not None
                and self.minimum > self.maximum):
            raise ValueError(f'{self.name}: minimum {self.minimum} > maximum {self.maximum}')
        unknown = set(self.inferred) - SPEC_FIELDS
        if unknown:
            raise ValueError(f'{self.name}: inferred names unknown fields {sorted(unknown)}')

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

    @property
    def title(self) -> str:
        """Return 'name (par. label)' for messages."""
        return f'{self.name} (par. {self.label or self.number})'


SPEC_FIELDS = frozenset(spec_field.name for spec_field in fields(ParameterSpec))


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
        reason = text_refusal(value)
        if reason:
            raise CommandRefused(f'{spec.name}: {reason}')
        # As many registers as the text needs, an odd length filled with a space; an empty
        # text as one register of spaces (a write carries 1 to 10 registers, manual 003
        # "Text Blocks": a write of none is refused with exception 66).
        try:
            return text_to_registers(value, max(2, len(value) + len(value) % 2))
        except (ValueError, UnicodeEncodeError) as error:
            raise CommandRefused(f'{spec.name}: {error}') from None
    raw = raw_number(spec, value, factors)
    if DATA_TYPES[spec.data_type][0] == 2:
        return list(split_u32(raw & 0xFFFFFFFF))
    return [raw & 0xFFFF]


def text_refusal(text: str) -> str:
    """
    Return why a device cannot store ``text`` ('' when it can).

    A text parameter holds one byte a character (Latin-1, as :func:`~drive_bridge.protocol.
    words.registers_to_text` reads it back) and ends at a NUL (the device keeps what is before
    it). So a character must be U+0001 to U+00FF.
    """
    refused = sorted({character for character in text if not 0 < ord(character) <= 0xFF})
    if not refused:
        return ''
    shown = ', '.join(repr(character) for character in refused[:5])
    more = f' and {len(refused) - 5} more' if len(refused) > 5 else ''
    return f'{text!r} has characters a device cannot store ({shown}{more}): text takes ' \
        'Latin-1 characters (U+0001 to U+00FF), one byte each, no NUL'


def raw_number(spec: ParameterSpec, value: Value, factors: Dict[int, float]) -> int:
    """Return the whole number on the bus for ``value`` (display units); raise CommandRefused."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise CommandRefused(f'{spec.name} takes a number, not {value!r}')
    _, _, minimum, maximum = DATA_TYPES[spec.data_type]
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
    return raw


def conversion_factor(spec: ParameterSpec, factors: Dict[int, float]) -> float:
    """Return the factor of the spec's conversion index, or raise for an unknown index."""
    try:
        return factors[spec.conversion]
    except KeyError:
        raise CommandRefused(f'{spec.name}: unknown conversion index {spec.conversion} '
                             f'(known: {", ".join(str(i) for i in sorted(factors))})') from None


# -- validation against a table entry (the CLI's restore checks a whole file first) --------
def check_value(spec: ParameterSpec, value: Value, factors: Dict[int, float]) -> Optional[str]:
    """
    Return why ``value`` (display units) does not fit ``spec``, or None when it fits.

    Checks, in order: text against a text parameter and its length; a number against the
    data type's range after conversion (and that it is a multiple of the conversion factor);
    the entry's minimum and maximum; and, for an enumeration whose options are all known,
    that the value is one of them.
    """
    if spec.data_type == TEXT:
        if not isinstance(value, str):
            return f'{spec.title} is a text parameter: {value!r} is not text'
        if len(value) > spec.characters:
            return f'{spec.title}: {value!r} is longer than {spec.characters} characters'
        reason = text_refusal(value)
        return f'{spec.title}: {reason}' if reason else None
    try:
        raw_number(spec, value, factors)
    except CommandRefused as error:
        return str(error).replace(spec.name, spec.title, 1)
    unit = f' {spec.unit}' if spec.unit else ''
    slack = conversion_factor(spec, factors) * 1e-6
    if spec.minimum is not None and value < spec.minimum - slack:
        return f'{spec.title}: {value}{unit} is below the minimum {spec.minimum:g}{unit}'
    if spec.maximum is not None and value > spec.maximum + slack:
        return f'{spec.title}: {value}{unit} is above the maximum {spec.maximum:g}{unit}'
    if spec.options and not spec.options_partial and value not in spec.options:
        known = ', '.join(f'{number} {name}' for number, name in sorted(spec.options.items()))
        return f'{spec.title}: {value} is not an option ({_shorten(known)})'
    return None


def check_values(specs: Mapping[int, ParameterSpec], values: Mapping[int, Value],
                 factors: Dict[int, float], settings_only: bool = True) -> List[str]:
    """
    Return one line per value of ``values`` (number -> value) that ``specs`` refuses.

    A number missing from ``specs`` is refused, and with ``settings_only`` so is a parameter
    the table marks as a readout (``setting`` False): a restore writes settings only.
    An empty list means every value fits.
    """
    reasons = []
    for number, value in values.items():
        spec = specs.get(number)
        if spec is None:
            reasons.append(f'parameter {number} is not in the table')
        elif settings_only and spec.setting is False:
            reasons.append(f'{spec.title} is a readout, not a setting: it is not restored')
        else:
            reason = check_value(spec, value, factors)
            if reason:
                reasons.append(reason)
    return reasons


def settings(specs: Iterable[ParameterSpec]) -> List[ParameterSpec]:
    """Return the entries a backup covers: those marked as settings, by number."""
    return sorted((spec for spec in specs if spec.setting), key=lambda spec: spec.number)


def _shorten(text: str, limit: int = 120) -> str:
    return text if len(text) <= limit else text[:limit - 3] + '...'
