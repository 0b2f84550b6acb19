"""
Which of a device's parameters a remote tool (ROS) gets, and what it may write. No I/O.

A device's parameters are those of its table (:func:`~drive_bridge.devices.parameter_info.
parameter_table`) that have a name: an MCD register the table knows only by its number is
left out (its meaning is not known, so nothing may be written to it remotely; ``drive-bridge
get``/``set``/``backup`` still reach it), and so is an array parameter (several values at
one number, e.g. FC 51 3-10 Preset Reference). Each is typed as ROS types it: text, a whole
number (conversion factor 1), or a double (any other factor), with its range in display
units: the table's minimum and maximum, else the data type's.

Read-only for remote tools: readouts (``setting`` False) and the device's own serial-line
settings (``serial_line``: protocol, address, baud rate, parity, and the MCD 3000's par. 20
that keeps it on the network; a write would cut the device off the line).

What a remote tool may write is narrower than the table where a value could keep a motor
running or start it, whoever asks (:func:`write_refusal`):

- FC 51 par. 8-04 (control word timeout function): only 2 (Stop) and 5 (Stop and trip), the
  options that stop the motor when the bus goes silent. Off (0) and Freeze output (1) leave
  it running (manual 004 section 5.6.2: frozen, only a coast, DC brake or digital input
  stops it), Jogging (3) and Max. speed (4) run it, and the FC series' other options (FC 102:
  7-10 select a set-up, 20 N2 override release) are not known to stop it.
- FC 51 par. 8-03 (control word timeout time): within the configuration's range of
  ``comms_timeout`` (0.1 s, the FC series' shortest, to 6000 s); a person sets either at
  commissioning, in the configuration, which the node writes at each connection.
- FC 51 par. 1-29 = 2 (Enable AMT): the motor is energised at the next start.
- MCD 3000 par. 20 (local/remote control): read-only (``serial_line``), and only 2 should
  that check be skipped: another value takes the starter off the network (manual 000 11.7).

The VLT 5000/6000 equivalents of 8-03/8-04 (bus time interval and its function: VLT 5000
par. 513/514, VLT 6000 par. 555/556) are in no table, so they are not offered.
"""

from dataclasses import dataclass, field
from typing import Any, Dict, List, Mapping, Optional, Tuple

from drive_bridge.devices.fc51_parameters import FC51_PARAMETERS
from drive_bridge.devices.fc_profile_drive import COMMS_TIMEOUT
from drive_bridge.devices.mcd_parameters import MCD3000
from drive_bridge.devices.parameter_names import designation, names_of, ros_name
from drive_bridge.devices.parameters import (
    conversion_factor, DATA_TYPES, ParameterSpec, TEXT)

TEXT_KIND, INTEGER_KIND, DOUBLE_KIND = 'string', 'integer', 'double'
AT_THE_DRIVE = 'set it at the drive'

# (family, parameter number) -> {value: why it is refused}: values that could run a motor.
MOTOR_VALUES: Dict[Tuple[str, int], Dict[Any, str]] = {
    ('fc', 804): {
        0: 'Off leaves the motor running when the bus goes silent',
        1: 'Freeze output keeps the motor at its speed when the bus goes silent (then only a '
           'coast, DC brake or digital input stops it, manual 004 section 5.6.2)',
        3: 'Jogging would run the motor at jog speed whenever the bus goes silent',
        4: 'Max. speed would run the motor at maximum speed whenever the bus goes silent',
    },
    ('fc', 129): {
        2: 'Enable AMT energises the motor (automatic motor tuning) at the next start',
    },
}


@dataclass(frozen=True)
class RemoteRule:
    """What a remote tool may write to one parameter: listed values only, or a narrower range."""

    allowed: Mapping[int, str] = field(default_factory=dict, hash=False)  # value -> meaning
    minimum: Optional[float] = None  # display units (a range rule)
    maximum: Optional[float] = None
    unit: str = ''
    why: str = ''  # why only these
    instead: str = AT_THE_DRIVE  # where another value is set

    def span(self) -> str:
        """Return what may be written, in words: '2 (Stop) and 5 (...)' or '0.1 to 6000 s'."""
        if self.allowed:
            return ' and '.join(f'{value} ({meaning})'
                                for value, meaning in sorted(self.allowed.items()))
        unit = f' {self.unit}' if self.unit else ''
        return f'{self.minimum:g} to {self.maximum:g}{unit}'

    def describe(self) -> str:
        """Return the rule in words for a descriptor."""
        return f'from ROS only {self.span()}: {self.why}'

    def refusal(self, value: Any) -> str:
        """Return why ``value`` (a number) is refused ('' when the rule takes it)."""
        taken = value in self.allowed if self.allowed else \
            self.minimum <= value <= self.maximum
        return '' if taken else f'{self.describe()}; {self.instead}'


# (family, parameter number) -> what a remote tool may write there (module docstring).
REMOTE_RULES: Dict[Tuple[str, int], RemoteRule] = {
    ('fc', 804): RemoteRule(
        allowed={2: 'Stop', 5: 'Stop and trip'},
        why='the options that stop the motor when the bus goes silent',
        instead='set comms_timeout_function in the node configuration at commissioning'),
    ('fc', 803): RemoteRule(
        minimum=0.1, maximum=COMMS_TIMEOUT.high, unit='s',
        why='the range of comms_timeout in the node configuration',
        instead='set comms_timeout in the node configuration at commissioning'),
    # Read-only already (serial_line); the rule holds the value should that check be skipped.
    # MCD 500 register 20 has no known meaning, so it is not offered (only named ones are).
    ('mcd', 20): RemoteRule(
        allowed={2: 'Local operation only'},
        why='another value takes the MCD 3000, and its stop, off the network (manual 000 '
            'section 11.7)',
        instead='set it at the starter'),
}
# The tables the rules' numbers are of, to find a parameter's rule without its family.
RULE_TABLES: Dict[str, Mapping[int, ParameterSpec]] = {
    'fc': FC51_PARAMETERS,
    'mcd': {entry.serial_number: entry.spec() for entry in MCD3000 if entry.serial_number},
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
    rule: Optional[RemoteRule] = None  # what a remote tool may write, beyond the table

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
        if self.rule is not None:
            parts.append(self.rule.describe())
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
        read_only = ("the device's own serial-line setting, or what keeps it on the network: a "
                     'write could cut it off the line; set it at the device')
    if spec.data_type == TEXT:
        return RemoteParameter(ros_name(spec), spec, TEXT_KIND, None, None, read_only)
    factor = conversion_factor(spec, dict(factors))
    _, _, low, high = DATA_TYPES[spec.data_type]
    minimum = spec.minimum if spec.minimum is not None else low * factor
    maximum = spec.maximum if spec.maximum is not None else high * factor
    rule = _rule_of(spec)
    if rule is not None and rule.minimum is not None:
        minimum, maximum = max(minimum, rule.minimum), min(maximum, rule.maximum)
    kind = INTEGER_KIND if factor == 1.0 else DOUBLE_KIND
    if kind == INTEGER_KIND:
        minimum, maximum = int(minimum), int(maximum)
    return RemoteParameter(ros_name(spec), spec, kind, minimum, maximum, read_only, rule)


def _rule_of(spec: ParameterSpec) -> Optional[RemoteRule]:
    for (family, number), rule in REMOTE_RULES.items():
        if RULE_TABLES[family].get(number) == spec:
            return rule
    return None


def write_refusal(family: str, spec: ParameterSpec, value: Any) -> str:
    """
    Return why ``value`` is not written remotely ('' when it may be).

    A value that could keep a motor running or start it (:data:`MOTOR_VALUES`), or one
    outside what a remote tool may write there (:data:`REMOTE_RULES`); the table's own check
    (:func:`~drive_bridge.devices.parameters.check_value`) comes after.
    """
    rule = REMOTE_RULES.get((family, spec.number))
    reason = MOTOR_VALUES.get((family, spec.number), {}).get(value)
    if reason:
        instead = rule.instead if rule is not None else AT_THE_DRIVE
        return f'{spec.title} = {value}: {reason}; not written from ROS ({instead})'
    if rule is None or isinstance(value, bool) or not isinstance(value, (int, float)):
        return ''
    reason = rule.refusal(value)
    return f'{spec.title} = {value}: {reason}' if reason else ''


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
