"""
The node's process: ``main``, the executor's thread, autostart and the exit signals.

SIGINT, SIGTERM and SIGHUP are blocked in every thread (:mod:`drive_bridge.ros.node.exit_signals`)
and taken by the main thread: the first one stops every motor that may run because of the
node, then the node exits; more signals meanwhile change nothing. The executor spins on a
thread of its own, so while the main thread stops the motors and closes the bus, calls are
still answered (refused: the bus is closing) and waiting ones are refused. Run it through
:mod:`drive_bridge.ros.node.entry`, which blocks the signals before this module's imports start
any thread.
"""

import signal
import sys
import threading
from typing import List, Optional

from drive_bridge.config.params_file import check_params_files
from drive_bridge.errors import ConfigError
from drive_bridge.ros.node.bridge_node import DriveBridgeNode
from drive_bridge.ros.node.exit_signals import ExitSignals
import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.lifecycle import TransitionCallbackReturn
from rclpy.signals import SignalHandlerOptions

USAGE = """usage: drive_bridge_node [--ros-args --params-file FILE [-r __ns:=/line1] ...]

The drive_bridge node: one RS-485 bus (or Modbus gateway) with its soft starters and drives,
as ROS 2 topics, services and parameters. Settings come from a ROS 2 parameters file; see
docs/configuration.md and config/*.yaml. Exit status: 0 after a signal, 2 on a configuration
error."""


def autostart(node: DriveBridgeNode) -> None:
    """Walk the node to active; raise ConfigError if the configuration is refused."""
    if node.configure_for_autostart() != TransitionCallbackReturn.SUCCESS:
        raise ConfigError(node.config_error or 'configure failed (see the log above)')
    if node.trigger_activate() != TransitionCallbackReturn.SUCCESS:
        raise ConfigError('activate failed (see the log above)')


def spin(executor: SingleThreadedExecutor, stop: threading.Event) -> None:
    """Spin until ``stop``; a context shut down under the executor ends it quietly."""
    while not stop.is_set():
        try:
            executor.spin_once(timeout_sec=0.5)
        except (ExternalShutdownException, KeyboardInterrupt):
            return
        except Exception as error:  # noqa: B902 - rclpy#398: the context went away
            if stop.is_set() or not rclpy.ok():
                return
            print(f'[drive_bridge] executor: {type(error).__name__}: {error}', file=sys.stderr,
                  flush=True)


def _configuration_error(text: str) -> None:
    print(f'[drive_bridge] configuration error: {text}', file=sys.stderr, flush=True)


def main(args: Optional[List[str]] = None) -> int:
    """Run the node until SIGINT/SIGTERM/SIGHUP; exit 2 with one line on a configuration error."""
    argv = sys.argv if args is None else args
    if '-h' in argv[1:] or '--help' in argv[1:]:
        print(USAGE)
        return 0
    try:
        check_params_files(argv)
    except ConfigError as error:
        _configuration_error(str(error))
        return 2
    # Block the exit signals in every thread from here on (threads inherit the mask): the
    # main thread takes them with sigtimedwait, so no KeyboardInterrupt ever lands inside a
    # stop, and a second signal cannot cut the stops short.
    exit_signals = ExitSignals()
    exit_signals.block()
    try:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    except Exception as error:  # noqa: B902 - rcl refuses its arguments: say why in one line
        reason = str(error).split(', at ')[0]
        _configuration_error(f'ROS could not take the arguments: {reason}')
        return 2
    return _run(exit_signals)


def _run(exit_signals: ExitSignals) -> int:
    """Run the node (rclpy is initialised) until an exit signal; stop, then shut down."""
    node: Optional[DriveBridgeNode] = None
    stop = threading.Event()
    spinner: Optional[threading.Thread] = None
    executor = SingleThreadedExecutor()
    exit_code = 0
    try:
        node = DriveBridgeNode()
        if node.autostart:
            autostart(node)
        executor.add_node(node)
        spinner = threading.Thread(target=spin, args=(executor, stop), name='ros-executor',
                                   daemon=True)
        spinner.start()
        received = exit_signals.wait(stop)
        signal_name = signal.Signals(received).name
        node.refuse_commands(signal_name)
        node.get_logger().info(f'{signal_name}: stopping the motors that may run because of '
                               'this node, then exiting')
    except ConfigError as error:
        _configuration_error(str(error))
        exit_code = 2
    finally:
        done = threading.Event()
        threading.Thread(target=exit_signals.ignore_more, args=(done,), daemon=True).start()
        if node is not None:
            node.shutdown_bus()
        stop.set()
        executor.shutdown(timeout_sec=1.0)
        if spinner is not None:
            spinner.join(timeout=2.0)
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
        done.set()
    return exit_code


if __name__ == '__main__':
    sys.exit(main())
