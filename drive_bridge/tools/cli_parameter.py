"""
``drive-bridge get`` and ``set``: one parameter by its manual number.

``set`` checks the value against the model's table before it writes, then reads it back.
"""

from dataclasses import replace
from typing import Any, Optional

from drive_bridge.devices import parameter_info as info
from drive_bridge.devices.parameters import ParameterSpec
from drive_bridge.tools import backup_file
from drive_bridge.tools.cli_session import parameter_options, Session, with_session
from drive_bridge.tools.cli_target import CliError, EXIT_OK, EXIT_USAGE


def value_line(session: Session, number: int, spec: Optional[ParameterSpec], value: Any,
               suffix: str = '') -> str:
    """Return 'label = value unit  # name (type)' for a parameter value."""
    shown_as = session.label(number)
    about = info.describe(spec, shown_as)
    text = f'{shown_as} = {info.format_value(spec, value, session.factors)}{suffix}'
    return text + (f'  # {about}' if about else '')


def command_get(args, out) -> int:
    """Print one parameter's value."""
    def get(session: Session) -> None:
        number = session.number(args.parameter)
        options = parameter_options(args)
        spec = session.typed_spec(args.parameter, number, options)
        value = session.parameter(number, options=options)
        print(value_line(session, number, spec, value), file=out)
    with_session(args, get)
    return EXIT_OK


def command_set(args, out) -> int:
    """Write one parameter (checked against the model's table first), then read it back."""
    def set_(session: Session) -> None:
        number = session.number(args.parameter)
        options = parameter_options(args)
        spec = session.typed_spec(args.parameter, number, options)
        value = info.parse_value(spec, args.value)
        if spec is not None:
            reason = backup_file.value_reason(spec, value, session.factors)
            if reason:
                raise CliError(f'{reason}: nothing written', EXIT_USAGE)
        session.parameter(number, value, replace(options, eeprom=args.eeprom))
        read = session.parameter(number, options=options)
        if not info.same_value(value, read):
            raise CliError(f'{session.label(number)}: wrote {value!r}, but it reads back '
                           f'{read!r}')
        print(value_line(session, number, spec, read, ' (written, read back)'), file=out)
    with_session(args, set_, writes=True)
    return EXIT_OK
