"""
The process's exit signals (SIGINT, SIGTERM, SIGHUP): blocked in every thread, taken by one.

The main thread takes them with ``sigtimedwait``, so no KeyboardInterrupt ever lands inside a
stop and a second signal cannot cut the stops short. Standard library only: the entry point
(:mod:`drive_bridge.ros.node.entry`) imports this module before anything that starts threads.
"""

import signal
import sys
import threading
from typing import List

EXIT_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


def block_in_this_thread() -> None:
    """Block the exit signals in this thread and in the threads it starts from now on."""
    signal.pthread_sigmask(signal.SIG_BLOCK, EXIT_SIGNALS)


def say_again(number: int) -> None:
    """Tell on stderr that a further exit signal changes nothing."""
    print(f'[drive_bridge] {signal.Signals(number).name} again: already stopping the '
          'motors, then exiting', file=sys.stderr, flush=True)


class ExitSignals:
    """
    The exit signals of the process, taken by the main thread.

    A thread started before the mask was set (when the node runs as ``python -m
    drive_bridge.ros.node.process`` rather than through :mod:`drive_bridge.ros.node.entry`) may
    still take one: Python then runs :meth:`_take_stray` in the main thread, which records it.
    """

    def __init__(self):
        self._received: List[int] = []

    def block(self) -> None:
        """Block the exit signals here and in later threads; take strays from earlier ones."""
        block_in_this_thread()
        for number in EXIT_SIGNALS:
            signal.signal(number, self._take_stray)

    def wait(self, stop: threading.Event) -> int:
        """Wait in the main thread for an exit signal (they are blocked); return its number."""
        while not stop.is_set() and not self._received:
            received = signal.sigtimedwait(EXIT_SIGNALS, 0.5)
            if received is not None:
                self._received.append(received.si_signo)  # later ones are "again"
                return received.si_signo
        return self._received[0] if self._received else 0

    @staticmethod
    def ignore_more(done: threading.Event) -> None:
        """During shutdown, take further exit signals and say they change nothing."""
        while not done.is_set():
            received = signal.sigtimedwait(EXIT_SIGNALS, 0.2)
            if received is not None:
                say_again(received.si_signo)

    def _take_stray(self, number: int, _frame) -> None:
        """Record an exit signal that a thread without the mask took; never raise."""
        if self._received:
            say_again(number)
        self._received.append(number)
