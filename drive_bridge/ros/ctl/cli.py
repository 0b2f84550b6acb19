"""
``drive_bridge_ctl``: command a running drive_bridge node from a terminal.

For machines without the ``ros2`` command line (ROS 2 from PyPI), it stands in for ``ros2
service call``, ``ros2 topic pub`` and ``echo``, ``ros2 param`` and ``ros2 lifecycle``
against the node. Everything goes through the node, so its rules hold: a monitor-only
device is never written to, an inactive node refuses commands, the node checks every value.
ROS_DOMAIN_ID, ROS_AUTOMATIC_DISCOVERY_RANGE and the other ROS settings come from the
environment, as for any ROS process. Exit status: 0 done; 1 the node refused or failed, or
did not answer in time; 2 bad input, or no such node, service, device or parameter (one
line on stderr, nothing sent); 130 interrupted; 141 the reader of the output went away
(``drive_bridge_ctl echo ... | head -1``), as SIGPIPE would end it, without a traceback.
Letting go of ROS after the command is bounded: a teardown that does not end within 10 s
(:data:`TEARDOWN_LIMIT_S`) ends the process by SIGALRM (exit status 142 in a shell), after
the command's own output.
"""

import argparse
import math
import os
import signal
import sys
import threading
from typing import List, Optional

from drive_bridge.console import drop_stdout, EXIT_BROKEN_PIPE, integer_argument, \
    number_argument, plain_text
from drive_bridge.ros.ctl import commands
from drive_bridge.ros.ctl.parameters import ParameterCommands
from drive_bridge.ros.ctl.session import BridgeSession, Interrupted
from drive_bridge.ros.ctl.values import BadInput, CtlError, node_name, reference_percent
import rclpy
from rclpy.signals import SignalHandlerOptions
from rclpy.utilities import remove_ros_args

PROG = 'drive_bridge_ctl'
DEFAULT_TIMEOUT_S = 10.0
MAX_RATE_HZ = 1000.0
# rclpy and Fast DDS let go of the command's node within this (about 50 ms as a rule); a CI
# run once saw the command's process spin at full CPU for 60 s after its output (not seen
# again in 570 runs): the alarm's default action then ends it, in the kernel, whatever holds
# the GIL, also in the C++ teardown after the interpreter's.
TEARDOWN_LIMIT_S = 10
EXAMPLES = """examples:
  drive_bridge_ctl call feeder/start              # ros2 service call /feeder/start ...
  drive_bridge_ctl reference feeder 40            # ros2 topic pub --once ... "{data: 40.0}"
  drive_bridge_ctl reference feeder 40 --rate 10  # a stream for reference_timeout
  drive_bridge_ctl param set feeder.speed_reference 40
  drive_bridge_ctl param get feeder.poll_rate
  drive_bridge_ctl state feeder
  drive_bridge_ctl echo feeder/motor_current --count 5
  drive_bridge_ctl lifecycle set deactivate
  drive_bridge_ctl --namespace /line1 call crusher/stop"""


class _Formatter(argparse.HelpFormatter):
    """Wrap the description; keep the examples' lines as they are."""

    def _fill_text(self, text: str, width: int, indent: str) -> str:
        if text.startswith('examples:'):
            return text
        return super()._fill_text(text, width, indent)


class _Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line (BadInput), not usage and exit."""

    def error(self, message: str):
        raise BadInput(f'{message} (see {self.prog} --help)')


def _options() -> argparse.ArgumentParser:
    """Return the options every command takes, before or after the command's name."""
    options = _Parser(add_help=False, argument_default=argparse.SUPPRESS)
    where = options.add_mutually_exclusive_group()
    where.add_argument('--node', dest='bridge_node', metavar='NAME',
                       help='the bridge node (default /drive_bridge)')
    where.add_argument('--namespace', dest='bridge_namespace', metavar='NS',
                       help="the bridge node's namespace: --namespace /line1 is --node "
                       '/line1/drive_bridge')
    options.add_argument('--timeout', type=number_argument, metavar='S',
                         help=f'seconds to wait for the node, and for each answer (default '
                         f'{DEFAULT_TIMEOUT_S:g})')
    return options


def _parser() -> argparse.ArgumentParser:
    options = _options()
    parser = _Parser(prog=PROG, parents=[options], epilog=EXAMPLES,
                     formatter_class=_Formatter,
                     description=plain_text(__doc__.split('\n\n')[1].strip()))
    sub = parser.add_subparsers(dest='command', required=True, metavar='COMMAND')

    def add(group, name: str, text: str, *arguments: str) -> argparse.ArgumentParser:
        command = group.add_parser(name, parents=[options], help=text, description=text)
        for argument in arguments:
            command.add_argument(argument, nargs='?' if argument == 'prefix' else None)
        return command
    add(sub, 'call', 'call a Trigger service of the node once (feeder/start, crusher/reset); '
        'exit status 1 if it answers success: false', 'service')
    command = add(sub, 'reference', 'publish a speed reference in percent to a drive, once '
                  '(delivered to the node) or at --rate HZ until Ctrl-C', 'device', 'percent')
    command.add_argument('--rate', type=number_argument, metavar='HZ',
                         help='publish at this rate until Ctrl-C or SIGTERM (a stream, for '
                         'reference_timeout)')
    add(sub, 'state', 'print the latched state of a device', 'device')
    command = add(sub, 'echo', "print the messages on a topic (relative names: in the node's "
                  'namespace) until Ctrl-C', 'topic')
    command.add_argument('--count', type=integer_argument, metavar='N',
                         help='stop after N messages (each within --timeout)')
    param = sub.add_parser('param', parents=[options],
                           help="get, set, list or describe the node's parameters")
    actions = param.add_subparsers(dest='action', required=True, metavar='ACTION')
    add(actions, 'get', 'print a parameter', 'name')
    add(actions, 'set', 'set a parameter, typed as the node declares it', 'name', 'value')
    add(actions, 'list', 'print the parameters (that start with PREFIX) with their values',
        'prefix')
    add(actions, 'describe', "print a parameter's type and meaning", 'name')
    lifecycle = sub.add_parser('lifecycle', parents=[options], help='get the lifecycle state, '
                               'list or set transitions (by label)')
    actions = lifecycle.add_subparsers(dest='action', required=True, metavar='ACTION')
    add(actions, 'get', 'print the lifecycle state')
    add(actions, 'list', 'print the transitions possible now')
    add(actions, 'set', 'make a transition: configure, activate, deactivate, cleanup or '
        'shutdown', 'label')
    return parser


def parse_args(argv: List[str]) -> argparse.Namespace:
    """Parse and check the command line; raise BadInput with one line."""
    args = _parser().parse_args(argv)
    args.bridge_chosen = hasattr(args, 'bridge_node') or hasattr(args, 'bridge_namespace')
    args.bridge_namespace, args.bridge_node = node_name(getattr(args, 'bridge_node', ''),
                                                        getattr(args, 'bridge_namespace', ''))
    args.timeout = getattr(args, 'timeout', DEFAULT_TIMEOUT_S)
    if not (math.isfinite(args.timeout) and args.timeout > 0):
        raise BadInput(f'--timeout must be a positive number of seconds, not {args.timeout}')
    if args.command == 'reference':
        args.percent = reference_percent(args.percent)
        if args.rate is not None and not (math.isfinite(args.rate) and
                                          0 < args.rate <= MAX_RATE_HZ):
            raise BadInput(f'--rate must be in (0, {MAX_RATE_HZ:g}] Hz, not {args.rate}')
    if args.command == 'echo' and args.count is not None and args.count < 1:
        raise BadInput(f'--count must be 1 or more, not {args.count}')
    if args.command == 'lifecycle' and args.action == 'set':
        args.label = commands.check_transition(args.label)
    return args


def run(session: BridgeSession, args: argparse.Namespace) -> int:
    """Run the command; return its exit status."""
    if args.command == 'call':
        return commands.call(session, args.service)
    if args.command == 'reference':
        return commands.reference(session, args.device, args.percent, args.rate)
    if args.command == 'state':
        return commands.state(session, args.device)
    if args.command == 'echo':
        return commands.echo(session, args.topic, args.count)
    if args.command == 'lifecycle':
        return commands.lifecycle(session, args.action, getattr(args, 'label', ''))
    params = ParameterCommands(session)
    if args.action == 'set':
        return params.set_value(args.name, args.value)
    if args.action == 'list':
        return params.list_values(args.prefix or '')
    return params.get(args.name) if args.action == 'get' else params.describe(args.name)


def _say(error: CtlError) -> int:
    print(f'{PROG}: {error}', file=sys.stderr, flush=True)
    return error.exit_status


def main(argv: Optional[List[str]] = None) -> int:
    """Run one command; see the module docstring for the exit status."""
    argv = sys.argv if argv is None else [PROG] + list(argv)
    try:
        args = parse_args(remove_ros_args(argv)[1:])
    except BadInput as error:
        return _say(error)
    stop = threading.Event()
    for number in (signal.SIGINT, signal.SIGTERM):
        signal.signal(number, lambda *_: stop.set())
    try:
        rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.NO)
    except Exception as error:  # noqa: B902 - rcl refuses its arguments: say why in one line
        return _say(BadInput(f'ROS could not take the arguments: '
                             f'{str(error).splitlines()[0]}'))
    node = rclpy.create_node(f'{PROG}_{os.getpid()}', start_parameter_services=False,
                             enable_rosout=False)
    session = BridgeSession(node, args.bridge_namespace, args.bridge_node, args.timeout, stop,
                            chosen=args.bridge_chosen)
    try:
        return run(session, args)
    except CtlError as error:
        return _say(error)
    except Interrupted as interrupted:
        print(f'{PROG}: interrupted' + (f': {interrupted}' if str(interrupted) else ''),
              file=sys.stderr, flush=True)
        return 130
    except BrokenPipeError:
        # The reader went away. A result prints after its act; `reference --rate` announces
        # its stream after the first message and sends no more once the announcement fails.
        drop_stdout()
        return EXIT_BROKEN_PIPE
    finally:
        signal.signal(signal.SIGALRM, signal.SIG_DFL)
        signal.alarm(TEARDOWN_LIMIT_S)
        session.close()
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == '__main__':
    sys.exit(main())
