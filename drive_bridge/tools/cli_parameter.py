"""
``drive-bridge get`` and ``set``: one parameter by its manual number.

``set`` checks the value against the model's table before it writes, then reads it back
(:meth:`drive_bridge.devices.parameter_service.ParameterService.write`).
"""

from dataclasses import replace
from typing import Any, Optional

from drive_bridge.devices import parameter_info as info
from drive_bridge.devices.contracts import ParameterOptions
from drive_bridge.devices.fc_profile_drive import FcProfileDrive
from drive_bridge.devices.parameter_service import ParameterService
from drive_bridge.devices.parameters import ParameterSpec
from drive_bridge.tools.cli_session import (
    parameter_options, PARAMETER_TYPES, Session, with_session)
from drive_bridge.tools.cli_target import CliError, EXIT_OK, EXIT_USAGE


def value_line(parameters: ParameterService, number: int, spec: Optional[ParameterSpec],
               value: Any, suffix: str = '') -> str:
    """Return 'label = value unit  # name (type)' for a parameter value."""
    shown_as = parameters.label(number)
    about = info.describe(spec, shown_as)
    text = f'{shown_as} = {info.format_value(spec, value, parameters.factors)}{suffix}'
    return text + (f'  # {about}' if about else '')


def typed_spec(parameters: ParameterService, typed: str, number: int,
               options: ParameterOptions) -> Optional[ParameterSpec]:
    """
    Return the spec of parameter ``number``; for a drive parameter not known, a CliError.

    The error says how ``typed`` was read (``3-99``: PNU 399) and which options describe
    a parameter outside the table.
    """
    spec = parameters.spec(number, options)
    if spec is not None or not isinstance(parameters.profile, FcProfileDrive):
        return spec
    shown_as = parameters.label(number)
    read_as = f'(PNU {number})' if shown_as == typed else \
        f'is read as {shown_as} (PNU {number}), which'
    raise CliError(f'parameter {typed} {read_as} is not in the {parameters.profile.model} '
                   f'table: give its data type with --type ({", ".join(PARAMETER_TYPES)}) '
                   'and its conversion index with --conversion (e.g. -2 for 0.01), as the '
                   'manual lists them', EXIT_USAGE)


def command_get(args, out) -> int:
    """Print one parameter's value."""
    def get(session: Session) -> None:
        parameters = session.parameters
        number = parameters.number(args.parameter)
        options = parameter_options(args)
        spec = typed_spec(parameters, args.parameter, number, options)
        value = parameters.read(number, options)
        print(value_line(parameters, number, spec, value), file=out)
    with_session(args, get)
    return EXIT_OK


def command_set(args, out) -> int:
    """Write one parameter (checked against the model's table first), then read it back."""
    def set_(session: Session) -> None:
        parameters = session.parameters
        number = parameters.number(args.parameter)
        options = parameter_options(args)
        spec = typed_spec(parameters, args.parameter, number, options)
        value = info.parse_value(spec, args.value)
        read = parameters.write(number, value, replace(options, eeprom=args.eeprom))
        print(value_line(parameters, number, spec, read, ' (written, read back)'), file=out)
    with_session(args, set_, writes=True)
    return EXIT_OK
