"""
What a ``drive-bridge`` command talks to: the bus and the device, from ``--config`` and options.

The parameters file is checked as the node checks it (a name the node refuses, such as a
misspelled ``baud_rate``, is refused here in the node's words:
:func:`drive_bridge.config.node_parameters.check_parameters_block`); options win over the
file. An option whose value does not fit is refused naming the option as it was typed
(``--address 300: allowed 1-247 for fc``), never the setting it becomes inside.
"""

import argparse
import shlex
from typing import Any, Dict, Iterable, Mapping, Tuple

from drive_bridge.config import model as cfg
from drive_bridge.config.node_parameters import check_parameters_block, split_parameters
from drive_bridge.config.params_file import select_block
from drive_bridge.errors import ConfigError
from drive_bridge.settings import check_value
from drive_bridge.transport.protocols import PROTOCOLS

EXIT_OK, EXIT_FAILED, EXIT_USAGE, EXIT_INTERRUPTED = 0, 1, 2, 130
BUS_OPTIONS = ('protocol', 'port', 'host', 'tcp_port', 'baudrate', 'parity', 'stopbits',
               'timeout', 'wire_trace')
DEVICE_OPTIONS = ('family', 'model', 'address', 'mcd_interface')
ADDRESSES = (1, 247)  # what any device address may be (the family or protocol may narrow it)


class CliError(Exception):
    """A failure to report in one line; ``code`` is the exit status."""

    def __init__(self, text: str, code: int = EXIT_FAILED):
        super().__init__(text)
        self.code = code


def option(name: str) -> str:
    """Return the command-line option of setting ``name`` (tcp_port: --tcp-port)."""
    return '--' + name.replace('_', '-')


def shown(value: Any) -> str:
    """Return an option's value as it would be typed (0.5, not 0.50000)."""
    return f'{value:g}' if isinstance(value, float) else str(value)


def given(args: argparse.Namespace, names: Iterable[str]) -> Dict[str, Any]:
    """Return the options of ``names`` that were given, by setting name."""
    return {name: getattr(args, name) for name in names
            if getattr(args, name, None) is not None}


# -- the parameters file ---------------------------------------------------------------------
def file_block(args: argparse.Namespace) -> Tuple[Dict[str, Any], Dict[str, Dict[str, Any]]]:
    """
    Return (bus values, device blocks) of the node block ``--config`` names ({}, {} if none).

    The block is refused as the node would refuse it for a name it does not know.
    """
    if not args.config:
        return {}, {}
    block = select_block(args.config, args.node)
    try:
        check_parameters_block(block)
    except ConfigError as error:
        raise ConfigError(f'{args.config}: {error} (the node refuses it too)') from None
    return split_parameters(block)


# -- the bus -------------------------------------------------------------------------------
def bus_values(args: argparse.Namespace, from_file: Mapping[str, Any]) -> Dict[str, Any]:
    """Return the bus settings: the file's, with the options given winning."""
    options = given(args, BUS_OPTIONS)
    if getattr(args, 'global_wire_trace', None) and 'wire_trace' not in options:
        options['wire_trace'] = args.global_wire_trace  # drive-bridge --wire-trace F COMMAND
    check_bus_options(options, from_file)
    bus = {key: value for key, value in from_file.items() if key != 'devices'}
    bus.update(options)
    spec = PROTOCOLS.get(bus.get('protocol', 'modbus_rtu'))
    if not args.config and spec is not None and spec.fixed_framing and 'parity' not in bus:
        bus['parity'] = spec.fixed_framing[0]  # --protocol ap_ascii: 8N1 without --parity N
    return bus


def check_bus_options(options: Mapping[str, Any], from_file: Mapping[str, Any]) -> None:
    """Refuse a bus option whose value does not fit, naming the option."""
    settings = {setting.name: setting for setting in cfg.BUS_SETTINGS}
    if options.get('port') == '':
        raise CliError('--port is empty: give the serial device, e.g. /dev/ttyUSB0', EXIT_USAGE)
    for name, value in options.items():
        try:
            check_value(settings[name], value, name)
        except ConfigError:
            raise CliError(f'{option(name)} {shown(value)}: allowed '
                           f'{settings[name].allowed()}', EXIT_USAGE) from None
    protocol = options.get('protocol', from_file.get('protocol', 'modbus_rtu'))
    spec = PROTOCOLS.get(protocol)
    if spec is None:
        return  # the file's protocol: refused in the file's words
    timeout = options.get('timeout')
    if timeout is not None and timeout < spec.min_timeout_s:
        raise CliError(f'--timeout {shown(timeout)}: allowed [{spec.min_timeout_s:g}, '
                       f'{settings["timeout"].high:g}] on protocol {protocol}', EXIT_USAGE)
    if spec.fixed_framing:
        parity, stopbits = spec.fixed_framing
        for name, fits in (('parity', (parity,)), ('stopbits', (0, stopbits))):
            if name in options and options[name] not in fits:
                raise CliError(f'{option(name)} {options[name]}: protocol {protocol} is always '
                               f'8{parity}{stopbits}: give {option(name)} {fits[-1]} or leave '
                               'it out', EXIT_USAGE)


# -- the device ------------------------------------------------------------------------------
def device_values(args: argparse.Namespace, from_file: Mapping[str, Any],
                  blocks: Mapping[str, Mapping[str, Any]], bus: Mapping[str, Any]) \
        -> Tuple[str, Dict[str, Any]]:
    """Return (name, settings) of the device: the file's block, options winning; or options."""
    options = given(args, DEVICE_OPTIONS)
    if args.config:
        name = args.device or (from_file.get('devices') or [None])[0]
        if name not in blocks:
            raise ConfigError(f'device {name!r} is not in {args.config}: it has '
                              f'{", ".join(blocks) or "no device blocks"}')
        values = dict(blocks[name], **options)
    else:
        name = option_device_name(args, options)
        values = dict(options)
    check_device_options(dict(given(args, BUS_OPTIONS), **options), values, bus)
    return name, values


def option_device_name(args: argparse.Namespace, options: Mapping[str, Any]) -> str:
    """
    Return the name of the device the options name: FAMILY_ADDRESS (fc_1, mcd_20).

    Without ``--config`` that is the only device there is: a ``--device`` naming another
    (a made-up ``fc_9``) is refused, naming the one there is.
    """
    if 'family' not in options or 'address' not in options:
        if args.device:
            raise CliError(f'--device {args.device}: device names come from --config FILE '
                           '(its devices list); without it give --family and --address (the '
                           'device is then named FAMILY_ADDRESS, e.g. fc_1)', EXIT_USAGE)
        raise ConfigError('name the device: --config FILE [--device NAME], or --family '
                          'with --address')
    name = f'{options["family"]}_{options["address"]}'
    if args.device and args.device != name:
        raise CliError(f'--device {args.device}: without --config the only device is {name} '
                       f'(--family {options["family"]} --address {options["address"]}); give '
                       '--config FILE to choose a device by name, or leave --device out',
                       EXIT_USAGE)
    return name


def check_device_options(options: Mapping[str, Any], values: Mapping[str, Any],
                         bus: Mapping[str, Any]) -> None:
    """Refuse a device option that does not fit the family and the bus, naming the option."""
    family = cfg.FAMILIES.get(values.get('family'))
    protocol = bus.get('protocol', 'modbus_rtu')
    spec = PROTOCOLS.get(protocol)
    if family is None or spec is None:
        return  # the file's family or protocol: refused in the file's words
    if ('family' in options or 'protocol' in options) and protocol not in family.protocols:
        raise CliError(f'family {family.name} does not run on protocol {protocol}: it runs '
                       f'on {", ".join(family.protocols)}', EXIT_USAGE)
    needed = [setting.name for setting in cfg.device_settings(family)
              if setting.default is None and setting.name not in values]
    if needed and 'family' in options:
        raise CliError(f'--family {family.name} needs --config: {" and ".join(needed)} are '
                       'settings that only a parameters file gives', EXIT_USAGE)
    model = values.get('model')
    if 'model' in options and model not in family.models:
        raise CliError(f'--model {model}: allowed {", ".join(family.models)} for family '
                       f'{family.name}', EXIT_USAGE)
    if model is None and 'auto' not in family.models:
        raise CliError(f'--family {family.name} needs --model ({" or ".join(family.models)}): '
                       'this family cannot tell its model', EXIT_USAGE)
    if 'address' in options:
        low, high, where = address_range(family, spec, bus)
        if not low <= options['address'] <= high:
            raise CliError(f'--address {options["address"]}: allowed {low}-{high} for '
                           f'{where}', EXIT_USAGE)


def address_range(family, spec, bus: Mapping[str, Any]) -> Tuple[int, int, str]:
    """Return (low, high, for what in words) of the addresses a device of ``family`` may have."""
    low, high = max(ADDRESSES[0], family.address_range[0]), \
        min(ADDRESSES[1], family.address_range[1])
    if spec.address_range is None:
        return low, high, family.name
    options = {setting.name: bus.get(setting.name, setting.default)
               for setting in spec.settings}
    carried = spec.address_range(options)
    if carried[0] <= low and high <= carried[1]:
        return low, high, family.name
    return max(low, carried[0]), min(high, carried[1]), f'{family.name} on protocol {spec.name}'


def make_bus(args: argparse.Namespace):
    """Return (BridgeConfig, DeviceConfig, bus values) for the device the arguments name."""
    from_file, blocks = file_block(args)
    bus = bus_values(args, from_file)
    name, values = device_values(args, from_file, blocks, bus)
    config = cfg.build_config(dict(bus, devices=[name]), {name: values})
    return config, config.devices[0], bus


# -- the command that restores a backup ------------------------------------------------------
def restore_command(args: argparse.Namespace, config, device, model: str) -> str:
    """
    Return the whole ``drive-bridge restore`` command for a backup of ``device``.

    With ``--config``: the same file, node block and device, and the options given here.
    Without: every bus setting and the device's family, model and address, so that the
    command needs nothing else.
    """
    words = ['drive-bridge', 'restore']
    if args.config:
        words += ['--config', str(args.config)] + (['--node', args.node] if args.node else [])
        words += ['--device', device.name]
        for name, value in given(args, BUS_OPTIONS + DEVICE_OPTIONS).items():
            words += [option(name), shown(value)]
    else:
        words += link_options(config.link, args)
        words += ['--family', device.family, '--model', model, '--address', str(device.address)]
    return shlex.join(words + [str(args.file)])


def link_options(link, args: argparse.Namespace) -> list:
    """Return the options that name ``link`` whole (and the timeout, if one was given)."""
    words = [] if link.protocol == 'modbus_rtu' else ['--protocol', link.protocol]
    if link.is_serial:
        words += ['--port', link.port, '--baudrate', str(link.baudrate), '--parity', link.parity]
        if link.stopbits:
            words += ['--stopbits', str(link.stopbits)]
    else:
        words += ['--host', link.host, '--tcp-port', str(link.tcp_port)]
    if args.timeout is not None:
        words += ['--timeout', shown(args.timeout)]
    return words
