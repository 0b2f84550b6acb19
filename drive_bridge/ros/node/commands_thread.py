"""
The thread that spins the node of the high-rate command subscriptions, and its executor.

rclpy's ``SingleThreadedExecutor`` rebuilds its wait set from every entity of every node it
holds on each wake-up, so a message costs more the more services, timers and parameter
services the node has. The command subscriptions (``~/joint_commands``, each
``<name>/speed_reference``) therefore live on a node of their own
(:mod:`drive_bridge.ros.node.command_inputs`) with nothing else on it, spun here by an executor
of its own on a thread of its own: rclpy's ``EventsExecutor`` where rclpy has it (Jazzy
7.1.4 on; it is fed by rcl's events instead of rebuilding a wait set, and takes exactly
what this node has: synchronous subscription callbacks, no guard conditions, no coroutines),
else a ``SingleThreadedExecutor``.

The thread calls ``spin_once`` with a timeout and looks at its stop flag in between: in
rclpy 7.1.6 the EventsExecutor's ``spin()`` and ``spin_once()`` without a timeout keep a
core busy and take nothing (seen on the development machine), and its ``wake()`` does not
end a ``spin_once`` that waits with a timeout (measured: the thread ended 0.29 s after
``wake()`` with a 0.5 s timeout). So the timeout is short, 0.05 s: the thread ends that
soon after :meth:`CommandsThread.stop` (each exit, deactivate and cleanup of the node
waited up to 0.5 s for it before), and an idle thread costs 0.3 % of a core (measured,
8 ms of CPU in 3 s). :meth:`CommandsThread.stop` ends the thread and waits for it, so once
it returns no callback of the node runs or will run: the node calls it before it closes the
bus. The
thread inherits the signal mask of the thread that starts it (the exit signals are blocked
in every thread, :mod:`drive_bridge.ros.node.exit_signals`).
"""

import sys
import threading
from typing import Optional

from drive_bridge.ros.node.spin_loop import spin_until_stopped
from rclpy.executors import Executor, SingleThreadedExecutor
from rclpy.node import Node

THREAD_NAME = 'ros-commands'
SPIN_TIMEOUT_S = 0.05  # the thread looks at its stop flag at least this often
JOIN_TIMEOUT_S = 5.0


def make_executor(node: Node) -> Executor:
    """Return rclpy's EventsExecutor for ``node``'s context, or a SingleThreadedExecutor."""
    try:
        from rclpy.experimental import EventsExecutor
    except ImportError:  # rclpy before 7.1.4
        return SingleThreadedExecutor(context=node.context)
    return EventsExecutor(context=node.context)


class CommandsThread:
    """One executor spinning one node on a thread of its own, from start to :meth:`stop`."""

    def __init__(self, node: Node):
        """Start spinning ``node`` (its subscriptions are made already)."""
        self._node = node
        self._stop = threading.Event()
        self._stopping = threading.Lock()  # one stop at a time (exit signal and lifecycle)
        self.executor = make_executor(node)
        self.executor.add_node(node)
        self._thread: Optional[threading.Thread] = threading.Thread(
            target=self._spin, name=THREAD_NAME, daemon=True)
        self._thread.start()

    def stop(self, timeout_s: float = JOIN_TIMEOUT_S) -> bool:
        """
        End the thread and wait for it; return whether it ended (idempotent).

        After a True return no callback of the node runs or will run. A callback that does
        not return within ``timeout_s`` (none of them waits for anything) leaves the thread
        running: False, said on stderr, and the next call waits for it again.
        """
        with self._stopping:
            thread = self._thread
            if thread is None:
                return True
            self._stop.set()
            self.executor.wake()
            thread.join(timeout_s)
            if thread.is_alive():
                print(f'[drive_bridge] {THREAD_NAME}: a command callback did not return within '
                      f'{timeout_s:g} s', file=sys.stderr, flush=True)
                return False
            self._thread = None
            self.executor.remove_node(self._node)
            self.executor.shutdown(timeout_sec=0.0)
            return True

    def _spin(self) -> None:
        """Spin until :meth:`stop`; a context shut down under the executor ends it quietly."""
        spin_until_stopped(self.executor, self._stop, self._node.context, THREAD_NAME,
                           SPIN_TIMEOUT_S)
