"""
``drive-bridge``: commission devices on a bus from a terminal, without ROS.

Subcommands: ``scan`` (find devices in an address range, tell family and model), ``status``
(one device, decoded), ``get``/``set`` (a parameter by its manual number, with conversion
and units), ``backup``/``restore`` (parameters to and from YAML, checked and verified) and
``monitor`` (live status). The bus comes from the node's parameters file (``--config
line.yaml --device conv``) or from options (``--port /dev/ttyUSB0 --family fc --address
1``).

Every transaction goes through the bus's transaction runner, as in the node: a write to a
monitor-only device (``allow_control: false``) is refused unless ``--force`` is given for
that command, a parameter number on process data or control registers is refused by the
profile, and an exception 04 is explained with the drive's register 7. Before a command's
first write the device at the address is identified with reads only, as ``scan`` does:
nothing is written to a device that does not answer as the family and model given (nor to
a silent address). ``restore`` checks the whole file (device, family, model, every number,
type, limit and option) before it writes anything. Progress goes to stderr, and only while
stderr is a terminal. Exit status: 0 done, 1 the bus or device failed, 2 a bad argument
or file, 130 interrupted (Ctrl-C), 141 the reader of stdout went away (``| head``).

This module holds the parser, :func:`main` and :func:`run_command`. The commands are in
``cli_status`` (status, monitor), ``cli_parameter`` (get, set), ``cli_backup`` (backup,
restore) and ``cli_scan``; what they share (:class:`Session`) in ``cli_session``, what
answers at an address in ``cli_identify``; the bus and the device from ``--config`` and
options in ``cli_target``. Parameter access and identification themselves are
:mod:`drive_bridge.devices.parameter_service` and :mod:`drive_bridge.devices.identification`,
which the node uses as well.
"""

import argparse
import logging
import math
import sys
import textwrap
from typing import List, Optional

from drive_bridge.config import model as cfg
from drive_bridge.console import drop_stdout, EXIT_BROKEN_PIPE, integer_argument, \
    number_argument, OneLineParser, parse_integer, parse_number
from drive_bridge.errors import CommandRefused, ConfigError, DriveBridgeError, ModelMismatch
from drive_bridge.tools.cli_backup import command_backup, command_restore
from drive_bridge.tools.cli_parameter import command_get, command_set
from drive_bridge.tools.cli_scan import command_scan
from drive_bridge.tools.cli_session import PARAMETER_TYPES
from drive_bridge.tools.cli_session import Session  # noqa: F401 (users import it from here)
from drive_bridge.tools.cli_status import command_monitor, command_status
from drive_bridge.tools.cli_target import CliError, EXIT_FAILED, EXIT_INTERRUPTED, EXIT_USAGE
from drive_bridge.tools.cli_wireshark import add_wireshark_command
from drive_bridge.tools.doctor import add_options as add_doctor_options, command_doctor
from drive_bridge.tools.trace_text import command_trace_text
from drive_bridge.transport.protocols import PROTOCOLS

DESCRIPTION = """\
Commission Danfoss soft starters (MCD) and drives (FC 51, VLT 5000/6000) on an RS-485 bus or
Modbus gateway, without ROS. The bus and the device come from the node's parameters file
(--config FILE --device NAME) or from options (--port, --family, --address).

Exit status: 0 done, 1 the bus or the device failed, 2 a bad argument or file,
130 interrupted (Ctrl-C), 141 the reader of stdout went away (| head). Progress is drawn on
stderr only when it is a terminal."""

EXAMPLES = {
    'scan': 'drive-bridge scan --port /dev/ttyUSB0 --addresses 1-32',
    'status': 'drive-bridge status --config config/mixed_bus.yaml --device feeder',
    'get': 'drive-bridge get --port /dev/ttyUSB0 --family fc --address 1 3-41\n'
           '  drive-bridge get --port /dev/ttyUSB0 --family vlt --model vlt5000 --address 5 '
           '205 --type int32 --conversion -3\n'
           '  drive-bridge get --config config/mixed_bus.yaml --device crusher 4',
    'set': 'drive-bridge set --port /dev/ttyUSB0 --family fc --address 1 3-41 4.25\n'
           '  drive-bridge set --port /dev/ttyUSB0 --family vlt --model vlt6000 --address 6 '
           '533 1234567890',
    'backup': 'drive-bridge backup --config config/mixed_bus.yaml --device feeder feeder.yaml',
    'restore': 'drive-bridge restore --config config/mixed_bus.yaml --device feeder '
               'feeder.yaml',
    'monitor': 'drive-bridge monitor --config config/mixed_bus.yaml --device feeder '
               '--count 3',
    'doctor': 'drive-bridge doctor --port /dev/ttyUSB0 --baudrate 19200 --address 3',
    'trace-text': 'drive-bridge trace-text line.pcapng > line.txt',
}

SUBCOMMANDS = {
    'scan': ('find devices in an address range',
             'Ask every address in the range what it is: as an FC-series drive (par. 15-40), '
             'as an MCD starter (product word 40007), then as a VLT 5000/6000 option card '
             '(status coils and par. 538, which both models have; the card cannot tell the '
             'model). An address that stays silent is skipped at once. Reads only.'),
    'status': ('one device, decoded', 'Poll one device once and print its decoded state, '
               'words, readouts and diagnostics. Reads only.'),
    'get': ('read a parameter by its manual number',
            'Read one parameter. Numbers as the manual writes them: FC 3-41 or 16-14, VLT '
            "205, MCD 4 (the Modbus Module's parameter number) or its designation (1-4). "
            'Values in display units (the conversion index applied), with the unit and the '
            'table entry. A number outside the built-in table needs --type and '
            '--conversion (drives). Reads only (a VLT text parameter writes the index '
            'register IND first).'),
    'set': ('write a parameter, then read it back',
            'Write one parameter and read it back. The value is checked first against the '
            "model's table (type, limits, options), and the device at the address is asked "
            'what it is, with reads only as scan asks: nothing is written if the value does '
            'not fit or the device does not answer as the family and model given. A text '
            'parameter takes the value as text (1234567890 stays text). Process data and '
            'control registers (FC 51 50000 CTW ...) are no parameters and are refused: use '
            "the node's commands. A device configured allow_control: false is refused unless "
            '--force is given.'),
    'backup': ('save all parameters to YAML and verify',
               "Read every setting of the device (drives: the settings of the model's "
               "table; MCD: parameters 1 to the model's last), read them all again, and "
               'save them if nothing changed in between. The file names the device, model, '
               'address and date, and for each parameter its number, PNU, name, unit and '
               'value; its first lines give the whole command that restores it. FILE must be '
               'new (--force overwrites it). Reads only.'),
    'restore': ('write a YAML backup back and verify',
                'Check the whole file first and write nothing unless all of it fits: family '
                'and model (never overridable), device name and address (--force to restore '
                "another device's backup), every number in the model's table and a "
                'setting, every value within its type, limits and options; and ask the device '
                'at the address what it is (reads only, as scan asks): nothing is written '
                'unless it answers as the family and model given. Then write each parameter '
                "in the file's order and read every one back. A failure or Ctrl-C part-way "
                'says which parameters were written.'),
    'doctor': ('check the port, adapter and line; find the devices',
               'Check the port (it exists, you may open it, its /dev/serial/by-id/ name), the '
               'USB adapter (driver; an FTDI latency timer, with the udev rule that sets it to '
               '1 ms), the line (quiet or babbling, local echo), then search the addresses '
               'over protocol (Modbus RTU, FC protocol, AP ASCII), baud rate and parity, the '
               'configured settings first. One line per finding, with its fix. Reads only. '
               'Exit status 0: devices answered and nothing is wrong; 1: a problem (each '
               'printed) or no device; 2: a bad argument.'),
    'monitor': ('live decoded status (Ctrl-C ends)',
                'Poll the device once a period and print one line each time, until Ctrl-C '
                '(exit status 130) or --count polls. Reads only.'),
    'trace-text': ('print a pcapng wire trace as text, one line a frame',
                   'Print a wire trace written to a .pcapng file (the wire_trace parameter, '
                   '--wire-trace) as the text form: time, line, TX or RX, the bytes, the '
                   'outcome, the duration and the unit; to paste into an issue. Opens no '
                   'port.'),
}


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser of ``drive-bridge``."""
    parser = OneLineParser(
        prog='drive-bridge', description=DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog='examples:\n' + '\n'.join(f'  {EXAMPLES[name]}' for name in
                                         ('scan', 'doctor', 'get', 'set', 'backup',
                                          'restore'))
        + '\n\n"drive-bridge COMMAND --help" tells more of each command.')
    parser.add_argument('--wire-trace', dest='global_wire_trace', metavar='FILE',
                        help="trace every frame of the command's bus to FILE (as each "
                        "command's --wire-trace)")
    commands = parser.add_subparsers(dest='command', required=True, metavar='COMMAND')
    add = _subcommand_adder(commands)
    scan = add('scan', command_scan, device=False)
    scan.add_argument('--addresses', default='1-32', help='address range (default 1-32)')
    scan.add_argument('--no-search', dest='search', action='store_false',
                      help='when nothing answers, do not search other protocols, baud rates '
                      'and parities (at the first addresses of the range)')
    add_doctor_options(add('doctor', command_doctor, device=False))
    add('status', command_status)
    get = add('get', command_get)
    get.add_argument('parameter', help='number as in the manual: FC 3-41, VLT 205, MCD 4 or 1-4')
    _parameter_options(get)
    set_ = add('set', command_set, writes=True)
    set_.add_argument('parameter', help='number as in the manual: FC 3-41, VLT 205, MCD 4')
    set_.add_argument('value', help='in display units (3.5 for 3.5 s), or the text of a text '
                      'parameter')
    _eeprom_option(set_)
    _parameter_options(set_)
    backup = add('backup', command_backup)
    backup.add_argument('file', help='the YAML file to write (a new file, unless --force)')
    backup.add_argument('--force', action='store_true', help='overwrite FILE if it exists')
    restore = add('restore', command_restore, writes=True)
    restore.add_argument('file', help='a backup written by drive-bridge backup')
    _eeprom_option(restore)
    monitor = add('monitor', command_monitor)
    monitor.add_argument('--period', type=positive_seconds, default=0.5,
                         help='seconds between polls (default 0.5)')
    monitor.add_argument('--count', type=poll_count, default=0,
                         help='stop after N polls (0: never)')
    add_wireshark_command(commands)
    summary, description = SUBCOMMANDS['trace-text']
    text = commands.add_parser('trace-text', help=summary,
                               description=textwrap.fill(description, 79),
                               epilog=f'example:\n  {EXAMPLES["trace-text"]}',
                               formatter_class=argparse.RawDescriptionHelpFormatter)
    text.set_defaults(function=command_trace_text)
    text.add_argument('file', help='a .pcapng wire trace')
    return parser


def positive_seconds(text: str) -> float:
    """Return ``text`` as a positive, finite number of seconds (an argparse type)."""
    try:
        value = float(parse_number(text))
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f'{text!r} is not a positive number of seconds')
    return value


def poll_count(text: str) -> int:
    """Return ``text`` as a whole number, 0 or more (an argparse type)."""
    try:
        count = parse_integer(text)
    except ValueError:
        count = -1
    if count < 0:
        raise argparse.ArgumentTypeError(f'{text!r} is not a whole number, 0 or more')
    return count


def _subcommand_adder(commands):
    def add(name: str, function, device: bool = True, writes: bool = False):
        summary, description = SUBCOMMANDS[name]
        sub = commands.add_parser(
            name, help=summary, description=textwrap.fill(description, 79),
            epilog=f'example:\n  '
            f'{EXAMPLES[name]}', formatter_class=argparse.RawDescriptionHelpFormatter)
        sub.set_defaults(function=function)
        bus = sub.add_argument_group('bus (default: from --config, else the node defaults)')
        bus.add_argument('--config', metavar='FILE',
                         help="the node's parameters file (YAML); options given here win")
        bus.add_argument('--node', help='the node block of --config (its full name, e.g. '
                         '/line1/drive_bridge) when the file has several')
        bus.add_argument('--protocol', choices=tuple(PROTOCOLS))
        bus.add_argument('--port', help='serial device or URL (default /dev/ttyUSB0)')
        bus.add_argument('--host', help='gateway host (modbus_tcp, rtu_over_tcp)')
        bus.add_argument('--tcp-port', dest='tcp_port', type=integer_argument,
                         help='gateway TCP port')
        bus.add_argument('--baudrate', type=integer_argument, help='default 9600')
        bus.add_argument('--parity', choices=('N', 'E', 'O'), help='default E')
        bus.add_argument('--stopbits', type=integer_argument, choices=(0, 1, 2),
                         help='0 (default): 2 with no parity, 1 with parity')
        bus.add_argument('--timeout', type=number_argument,
                         help='seconds per transaction (default 0.5)')
        bus.add_argument('--wire-trace', dest='wire_trace', metavar='FILE',
                         help='write every frame both ways to FILE, a .pcapng (Wireshark) or '
                         '.txt / .log (text); see docs/wire_trace.md')
        sub.add_argument('--quiet', action='store_true', help='no progress bar and no notes '
                         '(such as the pty note); warnings and errors still print')
        if device:
            chosen = sub.add_argument_group('device')
            chosen.add_argument('--device', help='device name in --config (default: the '
                                'first)')
            chosen.add_argument('--family', choices=sorted(cfg.FAMILIES))
            chosen.add_argument('--model', help='e.g. fc51, vlt6000, mcd500 (default auto; '
                                'VLT: required)')
            chosen.add_argument('--address', type=integer_argument)
            chosen.add_argument('--mcd-interface', dest='mcd_interface',
                                choices=('module', 'remote_operator'),
                                help='MCD: what sets the address: module (DIP switches, 1-31; '
                                'default but for the mcd3000) or remote_operator (1-99)')
        if writes:
            sub.add_argument('--force', action='store_true', help=FORCE_HELP[name])
        return sub
    return add


FORCE_HELP = {
    'set': 'write even though the device is configured allow_control: false (monitor only); '
           'a warning names it',
    'restore': 'restore to a device configured allow_control: false, or a backup taken of '
               'another device name or address (family and model must still match); a '
               'warning says so',
}


def _eeprom_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('--eeprom', action='store_true',
                        help='FC 51 and VLT 5000/6000: store the write in EEPROM as well as '
                        'RAM (coil 65); without it the drive keeps it in RAM only. MCD: does '
                        'not apply')


def _parameter_options(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group('drive parameters outside the built-in table (FC, VLT; '
                                      'MCD registers are raw 16-bit values)')
    group.add_argument('--type', choices=PARAMETER_TYPES,
                       help='data type (manual: "Type")')
    group.add_argument('--conversion', type=integer_argument,
                       help='conversion index, e.g. -2 for 0.01')
    group.add_argument('--index', type=integer_argument,
                       help='array index of an array parameter')


class _StderrLog(logging.Handler):
    """
    The package's log lines on stderr, as drive-bridge's.

    Notes (INFO: a pty opened without parity) only without ``--quiet``; warnings and
    errors always.
    """

    def __init__(self, quiet: bool = False):
        super().__init__(logging.WARNING if quiet else logging.INFO)

    def emit(self, record: logging.LogRecord) -> None:
        """Print the record's message in one line; a warning or error says so."""
        level = '' if record.levelno < logging.WARNING else f'{record.levelname}: '
        print(f'drive-bridge: {level}{record.getMessage()}', file=sys.stderr, flush=True)


def main(argv: Optional[List[str]] = None, out=sys.stdout) -> int:
    """Run ``drive-bridge``; return the exit status."""
    args = build_parser().parse_args(argv)
    logger = logging.getLogger('drive_bridge')
    handler = _StderrLog(getattr(args, 'quiet', False))
    logger.addHandler(handler)
    level = logger.level
    logger.setLevel(logging.INFO)
    try:
        return run_command(args, out)
    finally:
        logger.removeHandler(handler)
        logger.setLevel(level)


def run_command(args: argparse.Namespace, out) -> int:
    """Run the command ``args`` names; return the exit status, with failures in one line."""
    try:
        status = args.function(args, out)
        out.flush()  # a reader that went away shows here, not when Python exits
        return status
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
        print('drive-bridge: interrupted', file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        # The reader went away (`drive-bridge monitor ... | head -3`): the command has ended
        # (a write it made is done: each prints after its transaction).
        drop_stdout()
        return EXIT_BROKEN_PIPE


if __name__ == '__main__':
    sys.exit(main())
