"""
Text to ROS values and back for ``drive_bridge_ctl``: no node, no I/O.

A parameter value typed as the node declared it (``40`` goes to a double as 40.0), a speed
reference checked by the contract's rule before anything is sent, names taken in the
bridge node's namespace, and a message printed as ``ros2 topic echo`` prints it.
"""

import math
from typing import Any, List, Tuple

from drive_bridge.config import model as cfg
from drive_bridge.console import parse_integer, parse_number
from rcl_interfaces.msg import ParameterType, ParameterValue
from rclpy.exceptions import InvalidNamespaceException, InvalidNodeNameException, \
    InvalidServiceNameException, InvalidTopicNameException
from rclpy.parameter import get_parameter_value, Parameter, parameter_value_to_python
from rclpy.validate_full_topic_name import validate_full_topic_name
from rclpy.validate_namespace import validate_namespace
from rclpy.validate_node_name import validate_node_name
import yaml

BRIDGE_NODE = 'drive_bridge'
SPEED_REFERENCE = next(setting for setting in cfg.REFERENCE_SETTINGS
                       if setting.name == 'speed_reference')
TYPE_NAMES = {
    ParameterType.PARAMETER_NOT_SET: 'not set', ParameterType.PARAMETER_BOOL: 'bool',
    ParameterType.PARAMETER_INTEGER: 'integer', ParameterType.PARAMETER_DOUBLE: 'double',
    ParameterType.PARAMETER_STRING: 'string', ParameterType.PARAMETER_BYTE_ARRAY: 'byte array',
    ParameterType.PARAMETER_BOOL_ARRAY: 'bool array',
    ParameterType.PARAMETER_INTEGER_ARRAY: 'integer array',
    ParameterType.PARAMETER_DOUBLE_ARRAY: 'double array',
    ParameterType.PARAMETER_STRING_ARRAY: 'string array',
}
ARRAY_ELEMENTS = {
    ParameterType.PARAMETER_BOOL_ARRAY: ParameterType.PARAMETER_BOOL,
    ParameterType.PARAMETER_INTEGER_ARRAY: ParameterType.PARAMETER_INTEGER,
    ParameterType.PARAMETER_DOUBLE_ARRAY: ParameterType.PARAMETER_DOUBLE,
    ParameterType.PARAMETER_STRING_ARRAY: ParameterType.PARAMETER_STRING,
}


class CtlError(Exception):
    """A one-line answer of ``drive_bridge_ctl``; ``exit_status`` is its exit status."""

    exit_status = 1


class BadInput(CtlError):
    """An argument, a name or a value that cannot be used: nothing is sent (exit status 2)."""

    exit_status = 2


class Refused(CtlError):
    """The node refused or failed, or did not answer in time (exit status 1)."""


def _first_line(error: Exception) -> str:
    return str(error).splitlines()[0].split(': ', 1)[-1].rstrip(':')


def node_name(node: str = '', namespace: str = '') -> Tuple[str, str]:
    """Return (namespace, name) of ``--node`` (``/line1/drive_bridge``) or ``--namespace``."""
    if namespace:
        node = f'{namespace.rstrip("/")}/{BRIDGE_NODE}'
    full = '/' + (node or BRIDGE_NODE).strip('/')
    space, _, name = full.rpartition('/')
    space = space or '/'
    try:
        validate_namespace(space)
        validate_node_name(name)
    except (InvalidNamespaceException, InvalidNodeNameException) as error:
        raise BadInput(f'{full!r} is not a node name: {_first_line(error)}') from None
    return space, name


def resolve(name: str, namespace: str, is_service: bool = False) -> str:
    """Return ``name`` taken in ``namespace`` (an absolute name as it is); check it."""
    full = name if name.startswith('/') else f'{namespace.rstrip("/")}/{name}'
    try:
        validate_full_topic_name(full, is_service=is_service)
    except (InvalidTopicNameException, InvalidServiceNameException) as error:
        kind = 'service' if is_service else 'topic'
        raise BadInput(f'{name!r} is not a {kind} name: {_first_line(error)}') from None
    return full


def reference_percent(text: str) -> float:
    """Return a speed reference in percent; refuse what the node would refuse."""
    try:
        value = float(parse_number(text))
    except ValueError:
        raise BadInput(f'speed reference {text!r} is not a number: give percent, e.g. 40 or '
                       '-12.5; nothing sent') from None
    if not math.isfinite(value):
        raise BadInput(f'speed reference {text!r} is not a finite number; nothing sent')
    low, high = SPEED_REFERENCE.low, SPEED_REFERENCE.high
    if not (low <= value < high if SPEED_REFERENCE.high_open else low <= value <= high):
        raise BadInput(f'speed reference {value:g} % is out of range: allowed '
                       f'{SPEED_REFERENCE.allowed()} %; nothing sent')
    return value


def parameter_value(name: str, text: str, kind: int) -> ParameterValue:
    """
    Return ``text`` as a value of the parameter type ``kind`` (the node's declaration).

    A parameter without a type (not set) is guessed from the text as ``ros2 param set``
    does. Raise BadInput with the reason when the text is not of that type.
    """
    if kind == ParameterType.PARAMETER_NOT_SET:
        return get_parameter_value(text)
    if kind in ARRAY_ELEMENTS:
        value: Any = [_scalar(name, str(item), ARRAY_ELEMENTS[kind])
                      for item in _yaml_list(name, text, kind)]
    elif kind == ParameterType.PARAMETER_BYTE_ARRAY:
        raise BadInput(f'{name} is a byte array: not settable from here')
    else:
        value = _scalar(name, text, kind)
    return Parameter(name, Parameter.Type(kind), value).get_parameter_value()


def _yaml_list(name: str, text: str, kind: int) -> List[Any]:
    try:
        items = yaml.load(text, Loader=yaml.BaseLoader)  # text items: _scalar reads them
    except yaml.YAMLError:
        items = None
    if not isinstance(items, list):
        raise BadInput(f'{name} is a {TYPE_NAMES[kind]}: write [a, b, ...], not {text!r}')
    return items


def _scalar(name: str, text: str, kind: int) -> Any:
    if kind == ParameterType.PARAMETER_BOOL:
        if text.strip().lower() not in ('true', 'false'):
            raise BadInput(f'{name} is a bool: write true or false, not {text!r}')
        return text.strip().lower() == 'true'
    if kind == ParameterType.PARAMETER_INTEGER:
        try:
            return parse_integer(text)
        except ValueError:
            raise BadInput(f'{name} is an integer: write a whole number, not {text!r}') \
                from None
    if kind == ParameterType.PARAMETER_DOUBLE:
        try:
            value = float(parse_number(text))
        except ValueError:
            raise BadInput(f'{name} is a double: write a number, not {text!r}') from None
        if not math.isfinite(value):
            raise BadInput(f'{name} must be a finite number, not {text!r}')
        return value
    return text


def format_value(value: ParameterValue) -> str:
    """Return a parameter value as it would be written to ``param set``."""
    return _format(parameter_value_to_python(value))


def _format(value: Any) -> str:
    if value is None:
        return '(not set)'
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, list):
        return '[' + ', '.join(_format(item) for item in value) + ']'
    if isinstance(value, str) and not value:
        return "''"
    return str(value)


def message_fields(message: Any) -> Any:
    """Return a ROS message as plain dicts, lists and numbers (for YAML)."""
    if hasattr(message, 'get_fields_and_field_types'):
        return {field: message_fields(getattr(message, field))
                for field in message.get_fields_and_field_types()}
    if isinstance(message, bytes):
        return message[0] if len(message) == 1 else list(message)
    if hasattr(message, 'tolist'):  # numpy and array.array sequences
        message = message.tolist()
    if isinstance(message, (list, tuple)):
        return [message_fields(item) for item in message]
    return message


def message_text(message: Any) -> str:
    """Return a message as ``ros2 topic echo`` prints it: YAML, then ``---``."""
    text = yaml.safe_dump(message_fields(message), sort_keys=False, allow_unicode=True,
                          default_flow_style=False)
    return text.rstrip('\n') + '\n---'
