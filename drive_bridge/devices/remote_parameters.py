"""
Which of a device's parameters a remote tool (ROS) gets, and what it may write. No I/O.

A device's parameters are those of its table (:func:`~drive_bridge.devices.parameter_info.
parameter_table`) that have a name: an MCD register the table knows only by its number is
left out (its meaning is not known, so nothing may be written to it remotely; ``drive-bridge
get``/``set``/``backup`` still reach it), and so is an array parameter (several values at
one number, e.g. FC 51 3-10 Preset Reference). Each is typed as ROS types it: text, a whole
number (conversion factor 1), or a double (any other factor), with its range in display
units: the table's minimum and maximum, else the data type's.

Read-only for remote tools: readouts (``setting`` False) and the drive's own serial-line
settings (``serial_line``: protocol, address, baud rate, parity; a write would cut the drive
off the line). :func:`write_refusal` names the values that could make a motor run (FC 51
par. 8-04 Jogging or Max. speed: the drive runs the motor when the bus goes silent; 1-29
Enable AMT: the motor is energised at the next start): they are refused whoever asks.
"""

from dataclasses import dataclass
from typing import Any, Dict, List, Mapping, Optional, Tuple

from drive_bridge.devices.parameter_names import designation, names_of, ros_name
from drive_bridge.devices.parameters import (
    conversion_factor, DATA_TYPES, ParameterSpec, TEXT)

TEXT_KIND, INTEGER_KIND, DOUBLE_KIND = 'string', 'integer', 'double'

# (family, parameter number) -> {value: why it is refused}: values that could run a motor.
MOTOR_VALUES: Dict[Tuple[str, int], Dict[Any, str]] = {
    ('fc', 804): {
        3: 'Jogging would run the motor at jog speed whenever the bus goes silent',
        4: 'Max. speed would run the motor at maximum speed whenever the bus goes silent',
    },
    ('fc', 129): {
        2: 'Enable AMT energises the motor (automatic motor tuning) at the next start',
    },
}


@dataclass(frozen=True)
class RemoteParameter:
    """One device parameter as a remote tool sees it."""

    name: str  # the ROS name (parameter_names.ros_name)
    spec: ParameterSpec
    kind: str  # TEXT_KIND, INTEGER_KIND or DOUBLE_KIND
    minimum: Optional[float]  # display units; None for text
    maximum: Optional[float]
    read_only: str  # why it is read-only ('' if it is writable)

    @property
    def number(self) -> int:
        """Return the PNU (MCD: the module's Parameter N)."""
        return self.spec.number

    def description(self) -> str:
        """Return the manual's name, number, unit, type and source in one text."""
        spec = self.spec
        unit = f' [{spec.unit}]' if spec.unit else ''
        kind = 'text' if spec.data_type == TEXT else \
            f'{spec.data_type}, conversion index {spec.conversion}'
        return f'{spec.name}{unit}: par. {designation(spec)} ({kind}); source: {spec.source}'

    def constraints(self) -> str:
        """Return the options (value = meaning) and what else limits a value, in words."""
        parts: List[str] = []
        spec = self.spec
        if spec.options:
            options = ', '.join(f'{value} = {text}' for value, text in
                                sorted(spec.options.items()))
            partial = ' (others may be valid)' if spec.options_partial else ''
            parts.append(f'options: {options}{partial}')
        if spec.data_type == TEXT:
            parts.append(f'at most {spec.characters} characters')
        if self.read_only:
            parts.append(f'read-only: {self.read_only}')
        if spec.default is not None:
            parts.append(f'default {spec.default}')
        return '; '.join(parts)


def remote_parameters(table: Mapping[int, ParameterSpec],
                      factors: Mapping[int, float]) -> List[RemoteParameter]:
    """Return the parameters of ``table`` offered remotely, in the table's order."""
    offered = [spec for spec in table.values() if _offered(spec)]
    names_of(offered)  # refuses a table whose names collide
    return [_remote(spec, factors) for spec in offered]


def _offered(spec: ParameterSpec) -> bool:
    return spec.elements == 0 and spec.name != f'parameter {spec.number}'


def _remote(spec: ParameterSpec, factors: Mapping[int, float]) -> RemoteParameter:
    read_only = ''
    if spec.setting is False:
        read_only = 'a readout of the device, not a setting'
    elif spec.serial_line:
        read_only = ("the drive's own serial-line setting: a write would cut it off the "
                     'line; set it at the drive')
    if spec.data_type == TEXT:
        return RemoteParameter(ros_name(spec), spec, TEXT_KIND, None, None, read_only)
    factor = conversion_factor(spec, dict(factors))
    _, _, low, high = DATA_TYPES[spec.data_type]
    minimum = spec.minimum if spec.minimum is not None else low * factor
    maximum = spec.maximum if spec.maximum is not None else high * factor
    kind = INTEGER_KIND if factor == 1.0 else DOUBLE_KIND
    if kind == INTEGER_KIND:
        minimum, maximum = int(minimum), int(maximum)
    return RemoteParameter(ros_name(spec), spec, kind, minimum, maximum, read_only)


def write_refusal(family: str, spec: ParameterSpec, value: Any) -> str:
    """Return why writing ``value`` remotely could run a motor ('' when it could not)."""
    reason = MOTOR_VALUES.get((family, spec.number), {}).get(value)
    if not reason:
        return ''
    return f'{spec.title} = {value}: {reason}; not written from ROS (set it at the drive, ' \
        'or in the node configuration where it has a setting)'


def typed_value(parameter: RemoteParameter, value: Any) -> Tuple[Any, str]:
    """
    Return (the value in the parameter's type, '') or (None, why it does not fit the type).

    A whole number is taken for a double (``ros2 param set NODE NAME 7``) and a double
    that is a whole number for an integer (7.0); text only for text; a bool never.
    """
    name = parameter.name
    if parameter.kind == TEXT_KIND:
        if isinstance(value, str):
            return value, ''
        return None, f'{name} is text: give a string'
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None, f'{name} takes a number, not {value!r}'
    if parameter.kind == DOUBLE_KIND:
        return float(value), ''
    if isinstance(value, float):
        if not value.is_integer():
            return None, f'{name} is a whole number: {value} is not one'
        return int(value), ''
    return value, ''
