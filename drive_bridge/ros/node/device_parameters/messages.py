"""
Device parameters as rcl_interfaces messages: values, descriptors, parameter events.

A value goes out as its parameter's type (integer, double, string; see
:mod:`drive_bridge.devices.remote_parameters`); a value not held (never read, the device
offline) as ``PARAMETER_NOT_SET``. A descriptor carries the range in display units (an
``integer_range`` with step 1, or a ``floating_point_range`` without a step), the manual's
name, number, unit and source as its description, the options and the read-only reason in
``additional_constraints``, followed by the value's age (``value read 2.4 s ago``).
"""

from typing import Any, Iterable, Optional

from drive_bridge.devices.remote_parameters import (
    DOUBLE_KIND, INTEGER_KIND, RemoteParameter, TEXT_KIND)
from rcl_interfaces.msg import (
    FloatingPointRange, IntegerRange, Parameter, ParameterDescriptor, ParameterEvent,
    ParameterType, ParameterValue)

TYPES = {TEXT_KIND: ParameterType.PARAMETER_STRING,
         INTEGER_KIND: ParameterType.PARAMETER_INTEGER,
         DOUBLE_KIND: ParameterType.PARAMETER_DOUBLE}


def value_message(parameter: RemoteParameter, value: Optional[Any]) -> ParameterValue:
    """Return ``value`` as the parameter's type (None: PARAMETER_NOT_SET)."""
    if value is None:
        return ParameterValue(type=ParameterType.PARAMETER_NOT_SET)
    if parameter.kind == TEXT_KIND:
        return ParameterValue(type=TYPES[TEXT_KIND], string_value=str(value).rstrip(' '))
    if parameter.kind == INTEGER_KIND:
        return ParameterValue(type=TYPES[INTEGER_KIND], integer_value=int(value))
    return ParameterValue(type=TYPES[DOUBLE_KIND], double_value=float(value))


def python_value(message: ParameterValue) -> Any:
    """Return the Python value a ParameterValue carries (None: not set)."""
    kinds = {ParameterType.PARAMETER_BOOL: 'bool_value',
             ParameterType.PARAMETER_INTEGER: 'integer_value',
             ParameterType.PARAMETER_DOUBLE: 'double_value',
             ParameterType.PARAMETER_STRING: 'string_value',
             ParameterType.PARAMETER_BYTE_ARRAY: 'byte_array_value',
             ParameterType.PARAMETER_BOOL_ARRAY: 'bool_array_value',
             ParameterType.PARAMETER_INTEGER_ARRAY: 'integer_array_value',
             ParameterType.PARAMETER_DOUBLE_ARRAY: 'double_array_value',
             ParameterType.PARAMETER_STRING_ARRAY: 'string_array_value'}
    field = kinds.get(message.type)
    if field is None:
        return None
    value = getattr(message, field)
    return list(value) if message.type >= ParameterType.PARAMETER_BYTE_ARRAY else value


def age_text(age_s: Optional[float], error: str = '') -> str:
    """Return the value's age in words (or why the device refuses to read it)."""
    if error:
        return f'not readable: {error}'
    if age_s is None:
        return 'value not read yet (or the device is offline)'
    return f'value read {age_s:.1f} s ago'


def descriptor(parameter: RemoteParameter, age_s: Optional[float],
               error: str = '') -> ParameterDescriptor:
    """Return the descriptor of ``parameter``; its constraints end with the value's age."""
    constraints = parameter.constraints()
    message = ParameterDescriptor(
        name=parameter.name, type=TYPES[parameter.kind], description=parameter.description(),
        additional_constraints=(constraints + '; ' if constraints else '')
        + age_text(age_s, error),
        read_only=bool(parameter.read_only), dynamic_typing=False)
    if parameter.kind == INTEGER_KIND:
        message.integer_range = [IntegerRange(from_value=int(parameter.minimum),
                                              to_value=int(parameter.maximum), step=1)]
    elif parameter.kind == DOUBLE_KIND:
        message.floating_point_range = [FloatingPointRange(
            from_value=float(parameter.minimum), to_value=float(parameter.maximum), step=0.0)]
    return message


def event(node_fqn: str, stamp, changed: Iterable[Parameter]) -> ParameterEvent:
    """Return the /parameter_events message of ``changed`` values of node ``node_fqn``."""
    return ParameterEvent(stamp=stamp, node=node_fqn, changed_parameters=list(changed))
