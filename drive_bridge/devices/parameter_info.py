"""
What the bridge knows of a device's parameters: table, labels, value parsing and display. No I/O.

Drives (FC 51, VLT) have per-model tables in their profile (``parameter_table()``); MCD
starters' registers are raw 16-bit values, numbered 1 to the model's last, with the
entries manual 000 describes (:mod:`drive_bridge.devices.mcd_parameters`) laid over them.
"""

import math
from typing import Any, Dict, Mapping, Optional

from drive_bridge.console import parse_number
from drive_bridge.devices import mcd_parameters
from drive_bridge.devices.contracts import DeviceProfile, ParameterAccess, ParameterOptions
from drive_bridge.devices.fc_profile_drive import FcProfileDrive
from drive_bridge.devices.parameters import ParameterSpec, TEXT

RAW_FACTORS: Dict[int, float] = {0: 1.0}  # MCD registers: raw values
MAX_WHOLE_NUMBER = 2 ** 32  # beyond every register: a bigger value stays a float


def parameter_table(profile: DeviceProfile) -> Dict[int, ParameterSpec]:
    """Return PNU -> spec of every parameter the CLI knows for the profile's model."""
    if not isinstance(profile, ParameterAccess):
        return {}
    table = dict(profile.parameter_table())
    if table:
        return table
    # Raw registers (MCD): each number a uint16 setting, named where manual 000 names it.
    table = {number: ParameterSpec(number, f'parameter {number}', 'uint16', setting=True)
             for number in profile.parameter_numbers()}
    for entry in mcd_parameters.by_register(profile.model).values():
        if entry.serial_number in table:
            table[entry.serial_number] = entry.spec()
    return table


def conversion_factors(profile: DeviceProfile) -> Dict[int, float]:
    """Return the profile's conversion index -> factor table (raw registers: index 0 only)."""
    if isinstance(profile, FcProfileDrive):
        return profile.data.conversion_factors
    return RAW_FACTORS


def label(profile: DeviceProfile, number: int) -> str:
    """Return a parameter number as the device's manual writes it on the bus (FC: 3-41)."""
    if isinstance(profile, FcProfileDrive):
        return profile.data.parameter_label(number)
    return str(number)


def spec_for(profile: DeviceProfile, number: int, options: ParameterOptions,
             table: Optional[Mapping[int, ParameterSpec]] = None) -> Optional[ParameterSpec]:
    """
    Return how parameter ``number`` is read and written with ``options``, or None.

    The table's entry when the options do not change its type or conversion index; an
    entry the caller describes (``--type``, ``--conversion``) otherwise, without the
    table's limits; None for a number the table lacks and the options do not describe
    (the profile then refuses it in words).
    """
    known = (parameter_table(profile) if table is None else table).get(number)
    if options.data_type is None and options.conversion is None:
        return known
    if not isinstance(profile, FcProfileDrive):
        return known  # raw registers: the profile refuses options that do not apply
    if known is not None and options.data_type in (None, known.data_type) and \
            options.conversion in (None, known.conversion):
        return known
    if options.data_type is None and known is None:
        return None
    conversion = options.conversion if options.conversion is not None else \
        (known.conversion if known else 0)
    return ParameterSpec(number, known.name if known else f'parameter {number}',
                         options.data_type or known.data_type, conversion,
                         source='given on the command line',
                         label=label(profile, number))


def parse_value(spec: Optional[ParameterSpec], text: str) -> Any:
    """
    Return the value of ``text``: the text itself for a text parameter, else a number.

    A number is plain ASCII decimal (:func:`drive_bridge.console.parse_number`): ``1_5``,
    ``0x10`` or full-width digits stay text, which the table's check refuses. A whole number
    written with a fraction or an exponent (``1e3``, ``4.0``) is that integer.
    """
    if spec is not None and spec.data_type == TEXT:
        return text  # 1234567890 stays text on a text parameter
    try:
        value = parse_number(text)
    except ValueError:
        return text  # refused by the table's check as no number, in one line
    return whole_number(value)


def whole_number(value: Any) -> Any:
    """
    Return a float that is a whole number (``1e3``, ``1000.0``) as that int; else ``value``.

    An MCD register takes an int only; ``drive-bridge set`` and ``restore`` (a backup's
    ``1000.0``, as YAML reads it) both write the int.
    """
    if isinstance(value, float) and value.is_integer() and abs(value) <= MAX_WHOLE_NUMBER:
        return int(value)
    return value


def decimals(spec: ParameterSpec, factors: Mapping[int, float]) -> Optional[int]:
    """Return the decimal places of the spec's conversion factor (0.01: 2), None if not 10^n."""
    factor = factors.get(spec.conversion, 1.0)
    places = -math.log10(factor)
    return max(0, round(places)) if math.isclose(places, round(places)) else None


def display_value(spec: Optional[ParameterSpec], value: Any,
                  factors: Mapping[int, float]) -> Any:
    """Return ``value`` rounded to the spec's resolution (for printing and for backups)."""
    if spec is None or isinstance(value, (str, bool)) or not isinstance(value, float):
        return value
    places = decimals(spec, factors)
    return value if places is None else round(value, places)


def format_value(spec: Optional[ParameterSpec], value: Any,
                 factors: Mapping[int, float]) -> str:
    """Return ``value`` for a person: text in quotes, a number with the spec's unit."""
    if isinstance(value, str):
        return f'"{value}"'
    shown = display_value(spec, value, factors)
    unit = f' {spec.unit}' if spec is not None and spec.unit else ''
    return f'{shown}{unit}'


def describe(spec: Optional[ParameterSpec], shown_as: str) -> str:
    """Return what the spec is: name, type, and the manual's designation if not ``shown_as``."""
    if spec is None:
        return ''
    designation = f', par. {spec.label}' if spec.label and spec.label != shown_as else ''
    if spec.data_type == TEXT:
        kind = 'text'
    else:
        kind = f'{spec.data_type}, conversion index {spec.conversion}'
    return f'{spec.name} ({kind}{designation})'


def same_value(written: Any, read: Any) -> bool:
    """Return whether a value read back is the one written (numbers within rounding)."""
    if isinstance(written, str) or isinstance(read, str):
        return str(written).rstrip(' ') == str(read).rstrip(' ')
    try:
        return math.isclose(float(written), float(read), rel_tol=1e-9, abs_tol=1e-9)
    except (TypeError, ValueError):
        return written == read
