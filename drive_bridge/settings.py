"""
Settings as data: one parameter's name, type, default, limits and meaning, and its check.

Shared by the bus and device settings of :mod:`drive_bridge.config` and the settings each
device family and protocol declares for itself (:mod:`drive_bridge.devices.registry`), so a
bad value gets the same one-line message, naming the parameter and the allowed values,
wherever it comes from.
"""

from dataclasses import dataclass
import math
import reprlib
from typing import Any, Optional, Tuple

from drive_bridge.errors import ConfigError

MAX_SHOWN_CHARACTERS = 80
_SHORT_REPR = reprlib.Repr()
_SHORT_REPR.maxstring = _SHORT_REPR.maxother = MAX_SHOWN_CHARACTERS


@dataclass(frozen=True)
class Setting:
    """
    One parameter: name, Python type, default (None = required), limits and meaning.

    ``low``/``high`` bound numbers (``high_open``: high itself excluded); ``choices`` bound
    strings and ints; ``runtime`` settings may be changed with ``ros2 param set``.
    ``retired``: (value, what to do instead) for values an earlier release took.
    """

    name: str
    kind: type
    default: Any
    description: str
    low: Optional[float] = None
    high: Optional[float] = None
    choices: Tuple = ()
    runtime: bool = False
    high_open: bool = False
    retired: Tuple[Tuple[Any, str], ...] = ()

    def allowed(self) -> str:
        """Return the allowed values in words."""
        if self.choices:
            return ', '.join(str(choice) for choice in self.choices)
        if self.low is not None:
            closing = ')' if self.high_open else ']'
            return f'[{self.low:g}, {self.high:g}{closing}'
        return {bool: 'true or false', str: 'a string', int: 'an integer',
                float: 'a number', list: 'a list of names'}[self.kind]


def check_value(setting: Setting, value: Any, label: str) -> Any:
    """Return ``value`` checked against ``setting`` (ints accepted for floats), or raise."""
    if value is None:
        raise ConfigError(f'parameter {label!r} is required: allowed {setting.allowed()}')
    value = _coerce(setting, value, label)
    if setting.choices and value not in setting.choices:
        why = dict(setting.retired).get(value)
        raise ConfigError(f'parameter {label!r} = {shown(value)} is invalid: allowed '
                          f'{setting.allowed()}' + (f' ({why})' if why else ''))
    if setting.low is not None and not _in_range(setting, value):
        raise ConfigError(f'parameter {label!r} = {shown(value)} is out of range: allowed '
                          f'{setting.allowed()}')
    return value


def shown(value: Any) -> str:
    """
    Return the repr of ``value`` for a message, at most :data:`MAX_SHOWN_CHARACTERS` long.

    reprlib stops at a few items and levels, so a YAML alias bomb (a short file whose aliases
    expand to megabytes) is neither expanded into the message nor walked in full.
    """
    text = _SHORT_REPR.repr(value)
    if len(text) <= MAX_SHOWN_CHARACTERS:
        return text
    return text[:MAX_SHOWN_CHARACTERS - 3] + '...'


def _coerce(setting: Setting, value: Any, label: str) -> Any:
    if setting.kind is float and isinstance(value, int) and not isinstance(value, bool):
        value = float(value)
    if setting.kind is list:
        ok = isinstance(value, (list, tuple)) and all(isinstance(v, str) for v in value)
    else:
        ok = isinstance(value, setting.kind) and not (
            setting.kind is not bool and isinstance(value, bool))
    if not ok:
        hint = ''
        if setting.name == 'parity' and isinstance(value, bool):
            hint = ' (write parity: "N" with quotes: unquoted N is YAML false)'
        raise ConfigError(f'parameter {label!r} = {shown(value)} has the wrong type: allowed '
                          f'{setting.allowed()}{hint}')
    if setting.kind is float and (math.isnan(value) or math.isinf(value)):
        raise ConfigError(f'parameter {label!r} = {shown(value)} must be a finite number')
    return list(value) if setting.kind is list else value


def _in_range(setting: Setting, value: float) -> bool:
    if setting.high_open:
        return setting.low <= value < setting.high
    return setting.low <= value <= setting.high
