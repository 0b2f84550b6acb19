"""
The loop of a thread that spins an executor of its own (the command and parameter threads).

:func:`spin_until_stopped` calls ``spin_once`` with a timeout and looks at the thread's stop
flag in between (see :mod:`drive_bridge.ros.node.commands_thread` for why not ``spin()``). A
context shut down under the executor (the process ends) ends the loop quietly; any other
error of a callback is printed in one line and the loop goes on: a callback's bug must not
end the thread that serves the others.
"""

import sys
import threading

import rclpy
from rclpy.context import Context
from rclpy.executors import Executor, ExternalShutdownException


def spin_until_stopped(executor: Executor, stop: threading.Event, context: Context,
                       thread_name: str, spin_timeout_s: float) -> None:
    """Spin ``executor`` until ``stop`` is set or ``context`` is shut down."""
    while not stop.is_set():
        try:
            executor.spin_once(timeout_sec=spin_timeout_s)
        except (ExternalShutdownException, KeyboardInterrupt):
            return
        except Exception as error:  # noqa: B902 - a callback's bug must not end the thread
            if stop.is_set() or not rclpy.ok(context=context):
                return
            print(f'[drive_bridge] {thread_name}: {type(error).__name__}: {error}',
                  file=sys.stderr, flush=True)
