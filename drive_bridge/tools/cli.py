"""
``drive-bridge``: commission devices on a bus from a terminal, without ROS.

Subcommands: ``scan`` (find devices in an address range, tell family and model), ``status``
(one device, decoded), ``get``/``set`` (a parameter by its manual number, with conversion
and units), ``backup``/``restore`` (parameters to and from YAML, with progress and a verify
pass) and ``monitor`` (live status). The bus comes from the node's parameters file
(``--config line.yaml --device conv``) or from options (``--port /dev/ttyUSB0 --family fc
--address 1``). Exit status: 0 done, 1 the bus or device failed, 2 a bad argument.
"""

import argparse
import sys
import time
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

from drive_bridge import config as cfg
from drive_bridge.bus.device import BusDevice
from drive_bridge.bus.runner import run_poll, TransactionRunner
from drive_bridge.devices.contracts import DeviceReading, ParameterAccess, ParameterOptions
from drive_bridge.devices.drive import DriveProfile
from drive_bridge.devices.parameters import DATA_TYPES, TEXT
from drive_bridge.errors import (
    CommandRefused, ConfigError, DeviceException, DriveBridgeError, LinkDown, ModelMismatch,
    NoResponse, ProtocolError, TransportError)
from drive_bridge.transport.protocols import PROTOCOLS

EXIT_FAILED, EXIT_USAGE = 1, 2
SCAN_FAMILIES = ('fc', 'mcd', 'vlt')  # the order a scan tries them in (see scan_address)


class CliError(Exception):
    """A failure to report in one line; ``code`` is the exit status."""

    def __init__(self, text: str, code: int = EXIT_FAILED):
        super().__init__(text)
        self.code = code


# -- the bus and the device ----------------------------------------------------------------
def load_params_file(path: str, node: Optional[str] = None) \
        -> Tuple[Dict[str, Any], Dict[str, Dict[str, Any]]]:
    """Return (bus values, device blocks) of the node's block in a parameters file."""
    return cfg.split_parameters(cfg.select_block(path, node))


def bus_values_from(args: argparse.Namespace) -> Dict[str, Any]:
    """Return the bus settings given as options (only those given)."""
    names = ('protocol', 'port', 'host', 'tcp_port', 'baudrate', 'parity', 'stopbits',
             'timeout')
    return {name: getattr(args, name) for name in names if getattr(args, name) is not None}


def make_bus(args: argparse.Namespace, device_values: Optional[Dict[str, Any]] = None):
    """Return (BridgeConfig, DeviceConfig) for the device the arguments name."""
    if args.config:
        bus, devices = load_params_file(args.config, getattr(args, 'node', None))
        bus.update(bus_values_from(args))
        name = args.device or (bus.get('devices') or [None])[0]
        if name not in devices:
            raise ConfigError(f'device {name!r} is not in {args.config}: it has '
                              f'{", ".join(devices) or "no device blocks"}')
        values = dict(devices[name], **(device_values or {}))
    else:
        if args.family is None and device_values is None:
            raise ConfigError('name the device: --config FILE [--device NAME], or --family '
                              'with --address')
        bus = bus_values_from(args)
        name = f'{args.family}_{args.address}'
        values = {'family': args.family, 'address': args.address, 'model': args.model}
        values = {key: value for key, value in values.items() if value is not None}
        values.update(device_values or {})
    bus['devices'] = [name]
    config = cfg.build_config(bus, {name: values})
    return config, config.devices[0]


class Session:
    """
    One device on an open bus; transactions run here, in this thread.

    They go through the bus's transaction runner, so the same checks hold as in the node:
    a monitor-only device (``allow_control: false``) gets no write at all.
    """

    def __init__(self, config, device):
        self.config = config
        self.device = device
        self.record = BusDevice(device.make_spec(), time.monotonic())
        self.profile = self.record.profile
        self.transport = config.make_transport()
        self.runner = TransactionRunner(self.transport, config.timing.frame_gap_s)
        self.transport.connect()
        self._polled = False

    def close(self) -> None:
        """Close the port."""
        self.transport.close()

    def run(self, requests: Sequence[object]) -> list:
        """Run requests in order; a refusal is a CliError in the device's words."""
        results = []
        for request in requests:
            try:
                results.append(self.runner.transact(self.record, request))
            except DeviceException as error:
                raise CliError(f'{self.device.name} refused it: '
                               f'{self.runner.explain(self.record, error)}') from None
        return results

    def poll(self) -> DeviceReading:
        """Read the device once and return its decoded reading."""
        try:
            reading = run_poll(self.runner, self.record)
        except DeviceException as error:
            raise CliError(f'{self.device.name} refused the poll: '
                           f'{self.runner.explain(self.record, error)}') from None
        self._polled = True
        return reading

    def parameter(self, number: int, value=None, options: ParameterOptions = ParameterOptions()):
        """Read (value None) or write one parameter; return its value or the outcome."""
        if not isinstance(self.profile, ParameterAccess):
            raise CliError(f'{self.device.name} ({self.device.family}) has no parameter '
                           'access', EXIT_USAGE)
        if self.profile.configured_model == 'auto' and not self._polled:
            self.poll()  # model auto: the parameter map depends on what the device is
        plan = self.profile.parameter_plan(number, value, options)
        return plan.decode(self.run(plan.transactions))


# -- parameter numbers, values and tables ---------------------------------------------------
def parse_parameter_number(text: str) -> int:
    """Return the number of ``3-41`` (FC style: 341), ``16-14`` (1614) or ``205``."""
    group, dash, index = text.partition('-')
    try:
        if dash:
            if not index.isdigit() or len(index) != 2:
                raise ValueError
            return int(group) * 100 + int(index)
        return int(text)
    except ValueError:
        raise CliError(f'parameter number {text!r}: write it as in the manual, e.g. 3-41, '
                       '16-14 or 205', EXIT_USAGE) from None


def parse_value(text: str):
    """Return an int, a float or the text itself."""
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            continue
    return text


def parameter_options(args: argparse.Namespace, eeprom: bool = False) -> ParameterOptions:
    """Return the drive parameter options given (type, conversion index, array index)."""
    return ParameterOptions(data_type=getattr(args, 'type', None),
                            conversion=getattr(args, 'conversion', None),
                            index=getattr(args, 'index', None), eeprom=eeprom)


def describe_parameter(session: Session, number: int, options: ParameterOptions) -> str:
    """Return 'name' and where the definition came from, for drives; '' otherwise."""
    if not isinstance(session.profile, DriveProfile):
        return ''
    spec = session.profile.data.spec(number, options.data_type, options.conversion)
    return f'{spec.name} ({spec.data_type}, conversion index {spec.conversion})'


def backup_numbers(session: Session) -> List[int]:
    """Return the parameters a backup covers for this device."""
    profile = session.profile
    if profile.configured_model == 'auto':
        session.poll()  # model auto: the parameter count depends on the model
    numbers = list(profile.parameter_numbers()) if isinstance(profile, ParameterAccess) \
        else []
    if not numbers:
        raise CliError(f'{session.device.name} ({session.device.family}) has no parameter '
                       'access')
    return sorted(numbers)


def progress(done: int, total: int, label: str, stream=sys.stderr) -> None:
    """Draw a text progress bar on one line."""
    width = 30
    filled = width * done // max(1, total)
    stream.write(f'\r{label} [{"#" * filled}{"." * (width - filled)}] {done}/{total}')
    if done >= total:
        stream.write('\n')
    stream.flush()


# -- subcommands ----------------------------------------------------------------------------
def reading_lines(reading: DeviceReading) -> List[str]:
    """Return a reading as 'key: value' lines."""
    lines = [f'state: {reading.state}', f'status word: 0x{reading.status_word:04X}',
             f'trip: {reading.trip_code} {reading.trip_name}'.rstrip()]
    for label, value, unit in (('motor current', reading.motor_current_a, 'A'),
                               ('motor temperature', reading.motor_temperature_pct, '%'),
                               ('speed feedback', reading.speed_feedback_pct, '%')):
        if value is not None:
            lines.append(f'{label}: {value:.1f} {unit}')
    for label, word in (('alarm word', reading.alarm_word),
                        ('warning word', reading.warning_word)):
        if word is not None:
            lines.append(f'{label}: 0x{word:08X}')
    lines += [f'{key}: {value}' for key, value in reading.details.items()]
    lines += [f'warning: {text}' for text in reading.warnings]
    if reading.fault:
        lines.append(f'fault: {reading.fault}')
    return lines


def command_status(args, out) -> int:
    """Print one device's decoded status."""
    def status(session: Session) -> None:
        lines = reading_lines(session.poll())
        print(f'{session.device.name}: {session.device.family} {_model(session)} at address '
              f'{session.device.address}', file=out)
        for line in lines:
            print(f'  {line}', file=out)
    with_session(args, status)
    return 0


def _model(session: Session) -> str:
    return session.profile.model


def command_get(args, out) -> int:
    """Print one parameter's value."""
    number = parse_parameter_number(args.parameter)

    def get(session: Session) -> None:
        options = parameter_options(args)
        value = session.parameter(number, options=options)
        about = describe_parameter(session, number, options)
        print(f'{args.parameter} = {value}' + (f'  # {about}' if about else ''), file=out)
    with_session(args, get)
    return 0


def command_set(args, out) -> int:
    """Write one parameter, then read it back."""
    number = parse_parameter_number(args.parameter)
    value = parse_value(args.value)

    def set_(session: Session) -> None:
        options = parameter_options(args)
        print(session.parameter(number, value, parameter_options(args, args.eeprom)), file=out)
        print(f'{args.parameter} = {session.parameter(number, options=options)} (read back)',
              file=out)
    with_session(args, set_)
    return 0


def command_backup(args, out) -> int:
    """Read every parameter of a device into a YAML file, then verify it."""
    import yaml

    def backup(session: Session) -> None:
        numbers = backup_numbers(session)
        values = read_all(session, numbers, 'reading', args)
        verify = read_all(session, numbers, 'verifying', args)
        changed = [number for number in numbers if verify[number] != values[number]]
        if changed:
            raise CliError(f'{len(changed)} parameters changed while backing up (first: '
                           f'{changed[0]}): run the backup again with the device stopped')
        document = {'device': session.device.name, 'family': session.device.family,
                    'model': _model(session), 'address': session.device.address,
                    'parameters': values}
        with open(args.file, 'w') as stream:
            yaml.safe_dump(document, stream, sort_keys=False)
        print(f'{len(values)} parameters of {session.device.name} saved to {args.file} '
              'and verified', file=out)
    with_session(args, backup)
    return 0


def read_all(session: Session, numbers: List[int], label: str, args) -> Dict[int, Any]:
    """Read each parameter in ``numbers``, drawing progress."""
    values = {}
    for done, number in enumerate(numbers, 1):
        values[number] = session.parameter(number)
        if not args.quiet:
            progress(done, len(numbers), label)
    return values


def command_restore(args, out) -> int:
    """Write the parameters of a backup file, then read them back to verify."""
    document = load_backup(args.file)

    def restore(session: Session) -> None:
        if document.get('family') != session.device.family:
            raise CliError(f'{args.file} is a backup of a {document.get("family")} device; '
                           f'{session.device.name} is {session.device.family}', EXIT_USAGE)
        values = document['parameters']
        options = ParameterOptions(eeprom=args.eeprom)
        for done, (number, value) in enumerate(values.items(), 1):
            session.parameter(number, value, options)
            if not args.quiet:
                progress(done, len(values), 'writing')
        verify = read_all(session, list(values), 'verifying', args)
        different = {number: (values[number], verify[number]) for number in values
                     if verify[number] != values[number]}
        if different:
            number, (wanted, got) = next(iter(different.items()))
            raise CliError(f'verify failed for {len(different)} parameters (first: '
                           f'{number}: wrote {wanted!r}, reads {got!r})')
        print(f'{len(values)} parameters restored to {session.device.name} and verified',
              file=out)
    with_session(args, restore)
    return 0


def load_backup(path: str) -> Dict[str, Any]:
    """Return a backup document; raise CliError in words if it is not one."""
    import yaml
    try:
        with open(path) as stream:
            document = yaml.safe_load(stream)
    except OSError as error:
        raise CliError(f'cannot read {path}: {error.strerror}', EXIT_USAGE) from None
    except yaml.YAMLError as error:
        raise CliError(f'{path} is not valid YAML: {error}', EXIT_USAGE) from None
    parameters = document.get('parameters') if isinstance(document, dict) else None
    if not isinstance(parameters, dict) or not all(
            isinstance(number, int) for number in parameters):
        raise CliError(f'{path} is not a drive-bridge backup (no parameters: number -> '
                       'value map)', EXIT_USAGE)
    return document


def command_monitor(args, out) -> int:
    """Print the decoded status once a period until Ctrl-C (or --count polls)."""
    def monitor(session: Session) -> None:
        polls = 0
        while args.count == 0 or polls < args.count:
            started = time.monotonic()
            try:
                line = '  '.join(reading_lines(session.poll())[:6])
            except (TransportError, CliError) as error:
                line = f'no reading: {error}'
            print(f'{time.strftime("%H:%M:%S")}  {line}', file=out, flush=True)
            polls += 1
            time.sleep(max(0.0, args.period - (time.monotonic() - started)))
    with_session(args, monitor)
    return 0


def command_scan(args, out) -> int:
    """Try every address in the range; print what answers, with family and model."""
    first, last = parse_range(args.addresses)
    bus = bus_values_from(args)
    found = 0
    for address in range(first, last + 1):
        result = scan_address(bus, address)
        if not args.quiet:
            progress(address - first + 1, last - first + 1, 'scanning')
        if result:
            found += 1
            print(f'address {address}: {result}', file=out)
    print(f'{found} device(s) found at addresses {first}-{last}', file=out)
    return 0


def parse_range(text: str) -> Tuple[int, int]:
    """Return (first, last) of ``1-32`` or ``5``."""
    first, _, last = text.partition('-')
    try:
        low, high = int(first), int(last or first)
    except ValueError:
        raise CliError(f'address range {text!r}: write it as 1-32', EXIT_USAGE) from None
    if not 1 <= low <= high <= 247:
        raise CliError(f'address range {text!r} must lie within 1-247, low to high',
                       EXIT_USAGE)
    return low, high


def scan_address(bus: Dict[str, Any], address: int) -> str:
    """
    Return what answers at ``address`` in words, or '' if nothing does.

    FC-series drives are asked for their type text (par. 15-40) first, then MCD starters
    for their product word (40008); a device that answers neither but takes FC-profile
    reads is reported as a VLT option card (the card cannot tell its model).
    """
    for family in SCAN_FAMILIES:
        if family == 'mcd' and address > 99:
            continue
        values = {'family': family, 'address': address,
                  'model': 'vlt5000' if family == 'vlt' else 'auto'}
        try:
            config = cfg.build_config(dict(bus, devices=['probe']), {'probe': values})
        except ConfigError:
            continue
        session = None
        try:
            session = Session(config, config.devices[0])
            reading = session.poll()
        except LinkDown as error:
            raise CliError(str(error)) from None
        except NoResponse:
            return ''  # nothing at this address: do not try the other families
        except (TransportError, CliError, ModelMismatch, ProtocolError, ValueError,
                IndexError):
            continue
        finally:
            if session is not None:
                session.close()
        if family == 'vlt':
            return 'vlt (VLT 5000/6000 option card: set model vlt5000 or vlt6000), ' \
                   f'state {reading.state}'
        return f'{family} {_model(session)}, state {reading.state}'
    return 'something answers, but not as any supported family'


def with_session(args, action: Callable[[Session], None]) -> None:
    """Open the bus for the named device, run ``action``, close the bus."""
    config, device = make_bus(args)
    session = Session(config, device)
    try:
        action(session)
    finally:
        session.close()


# -- command line ---------------------------------------------------------------------------
def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser of ``drive-bridge``."""
    parser = argparse.ArgumentParser(
        prog='drive-bridge', description='Commission Danfoss starters and drives on a bus '
        '(no ROS needed).')
    commands = parser.add_subparsers(dest='command', required=True)
    add = _subcommand_adder(commands)
    scan = add('scan', command_scan, 'find devices in an address range', device=False)
    scan.add_argument('--addresses', default='1-32', help='address range, e.g. 1-32')
    add('status', command_status, 'one device, decoded')
    get = add('get', command_get, 'read a parameter by its manual number')
    get.add_argument('parameter', help='e.g. 3-41 (FC), 205 (VLT), 4 (MCD)')
    _parameter_options(get)
    set_ = add('set', command_set, 'write a parameter, then read it back')
    set_.add_argument('parameter')
    set_.add_argument('value', help='in display units (e.g. 3.5 for 3.5 s)')
    set_.add_argument('--eeprom', action='store_true', help='FC: store in EEPROM too')
    _parameter_options(set_)
    backup = add('backup', command_backup, 'save all parameters to YAML and verify')
    backup.add_argument('file')
    restore = add('restore', command_restore, 'write a YAML backup back and verify')
    restore.add_argument('file')
    restore.add_argument('--eeprom', action='store_true', help='FC: store in EEPROM too')
    monitor = add('monitor', command_monitor, 'live decoded status (Ctrl-C ends)')
    monitor.add_argument('--period', type=float, default=0.5, help='seconds between polls')
    monitor.add_argument('--count', type=int, default=0, help='stop after N polls (0: never)')
    return parser


def _subcommand_adder(commands):
    def add(name: str, function, help_text: str, device: bool = True):
        sub = commands.add_parser(name, help=help_text, description=help_text)
        sub.set_defaults(function=function)
        bus = sub.add_argument_group('bus (default: from --config, else the node defaults)')
        bus.add_argument('--config', help="the node's parameters file (YAML)")
        bus.add_argument('--protocol', choices=tuple(PROTOCOLS))
        bus.add_argument('--node', help='the node block of --config (its full name, e.g. '
                         '/line1/drive_bridge) when the file has several')
        bus.add_argument('--port', help='serial device or URL, e.g. /dev/ttyUSB0')
        bus.add_argument('--host')
        bus.add_argument('--tcp-port', dest='tcp_port', type=int)
        bus.add_argument('--baudrate', type=int)
        bus.add_argument('--parity', choices=('N', 'E', 'O'))
        bus.add_argument('--stopbits', type=int, choices=(0, 1, 2))
        bus.add_argument('--timeout', type=float, help='seconds per transaction')
        sub.add_argument('--quiet', action='store_true', help='no progress bar')
        if device:
            chosen = sub.add_argument_group('device')
            chosen.add_argument('--device', help='device name in --config')
            chosen.add_argument('--family', choices=sorted(cfg.FAMILIES))
            chosen.add_argument('--model')
            chosen.add_argument('--address', type=int)
        return sub
    return add


def _parameter_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('--type', choices=sorted(DATA_TYPES) + [TEXT],
                        help='drives: data type of a parameter not in the built-in table')
    parser.add_argument('--conversion', type=int, help='drives: conversion index')
    parser.add_argument('--index', type=int, help='drives: array index')


def main(argv: Optional[List[str]] = None, out=sys.stdout) -> int:
    """Run ``drive-bridge``; return the exit status."""
    args = build_parser().parse_args(argv)
    try:
        return args.function(args, out)
    except CliError as error:
        print(f'drive-bridge: {error}', file=sys.stderr)
        return error.code
    except (ConfigError, CommandRefused) as error:
        print(f'drive-bridge: {error}', file=sys.stderr)
        return EXIT_USAGE
    except (DriveBridgeError, ModelMismatch) as error:
        print(f'drive-bridge: {error}', file=sys.stderr)
        return EXIT_FAILED
    except KeyboardInterrupt:
        return 0


if __name__ == '__main__':
    sys.exit(main())
