"""
Benchmark: where a transaction's CPU goes in the bus thread, piece by piece (issue 43).

The bus alone (``BusMaster``, no ROS, no listener) polls 4 MCD 500 and 4 FC 51 at 100 Hz on
a line paced by the wire pacer (as ``node_cpu.py``). A first bus runs one window as it is:
its thread's CPU a transaction (``time.thread_time``) is the total. A second bus on the same
line then runs one window with the methods of each piece wrapped, so that the thread's CPU
spent inside a piece, less the pieces it calls, is added to it: the port's system calls
(``select``, ``read``, ``write``, ``tcsetattr`` for VMIN), the port's Python
(``transport/serial_port``), the line discipline (``exchange``, ``reply_window``), the
framer and codecs, the poll cycle (the device profile building requests and decoding
replies), the runner, scheduling, health and the deadman, and the hand-off of events. A
wrapper's own bookkeeping after the call is kept out of the caller's piece; what the
wrappers cost in all is the difference between the two windows, printed beside the table
(it falls mostly on the pieces with many calls). Figures are per transaction on the wire,
with the calls a transaction makes. The pacer runs in this process (its thread shares the
interpreter), so the figures are for comparing pieces and versions on one machine, not for
the node's total (``node_cpu.py``, ``master_cpu.py``). To compare two versions run it with
each on ``PYTHONPATH``.
Run: .venv/bin/python bench/bus_pieces.py [window seconds] [baud rate, default 19200]
"""

import argparse
import os
import select
import sys
import termios
import threading
import time
import types
from typing import Callable, Dict, List, Tuple

from drive_bridge.bus.master import BusMaster
from drive_bridge.config.model import build_config
from drive_bridge.sim.wire_pacer import LineTiming
from drive_bridge.transport.engines import make_transport
from paced_line import LINE_DEVICES, node_bus, PacedSimulator, simulator_devices
import thread_cpu

WARM_UP_S = 2.0
PORT_CALLS = 'system calls: '


class Pieces:
    """Thread CPU a piece, exclusive of the pieces it calls, and the calls of each."""

    def __init__(self):
        self.cpu_s: Dict[str, float] = {}
        self.calls: Dict[str, int] = {}
        self._stack = threading.local()

    def wrap(self, piece: str, function: Callable) -> Callable:
        """Return ``function`` with its exclusive CPU added to ``piece``."""
        clock, cpu_s, calls, local = time.thread_time, self.cpu_s, self.calls, self._stack

        def wrapped(*args, **kwargs):
            stack = local.__dict__.setdefault('nested', [])
            stack.append(0.0)
            started = clock()
            try:
                return function(*args, **kwargs)
            finally:
                elapsed = clock() - started
                inner = stack.pop()
                cpu_s[piece] = cpu_s.get(piece, 0.0) + elapsed - inner
                calls[piece] = calls.get(piece, 0) + 1
                if stack:  # the caller's piece excludes this call and its bookkeeping
                    stack[-1] += clock() - started
        return wrapped

    def wrap_methods(self, cls: type, names: Tuple[str, ...], piece: str) -> None:
        """Wrap the methods ``names`` of ``cls`` (static ones stay static)."""
        for name in names:
            raw = cls.__dict__[name]
            if isinstance(raw, staticmethod):
                setattr(cls, name, staticmethod(self.wrap(piece, raw.__func__)))
            else:
                setattr(cls, name, self.wrap(piece, raw))


def install(pieces: Pieces) -> None:
    """Wrap the pieces of the bus and the transport (this process only)."""
    from drive_bridge.bus import deadman, health, jobs, outbox, polling, runner, scheduler
    from drive_bridge.protocol import rtu
    from drive_bridge.transport import exchange, line_transport, reply_window, serial_port
    from drive_bridge.transport import serial_rtu
    wrap = pieces.wrap
    serial_port.select = types.SimpleNamespace(select=wrap(PORT_CALLS + 'select', select.select))
    serial_port.os = types.SimpleNamespace(
        read=wrap(PORT_CALLS + 'read', os.read), write=wrap(PORT_CALLS + 'write', os.write),
        name=os.name, set_blocking=os.set_blocking)
    serial_port.termios = types.SimpleNamespace(**{
        name: getattr(termios, name) for name in dir(termios) if not name.startswith('_')})
    serial_port.termios.tcsetattr = wrap(PORT_CALLS + 'tcsetattr (VMIN)', termios.tcsetattr)
    pieces.wrap_methods(serial_port.SerialLine, (
        'read', 'write', 'wait_quiet', '_read_descriptor', '_set_vmin'),
        'transport: the port (serial_port)')
    discipline = 'transport: line discipline (exchange, reply_window)'
    pieces.wrap_methods(exchange.LineDiscipline, ('begin', 'exchange', 'done', 'failed',
                                                  '_take'), discipline)
    pieces.wrap_methods(reply_window.ReplyWindow, ('__init__', 'read', '_answer',
                                                   '_end_of_frame'), discipline)
    pieces.wrap_methods(line_transport.LineTransport, ('execute', '_transact'),
                        'transport: execute (line_transport)')
    codec = 'protocol: request frame, framer, CRC, reply check'
    pieces.wrap_methods(serial_rtu.RtuSerialTransport, ('_run',), codec)
    serial_rtu.accept_reply = wrap(codec, serial_rtu.accept_reply)
    pieces.wrap_methods(rtu.ReplyFramer, ('cut',), codec)
    pieces.wrap_methods(runner.PollRun, ('next_step',),
                        'devices: poll cycle (requests built, replies decoded)')
    pieces.wrap_methods(runner.TransactionRunner, ('transact', '_ended'),
                        'bus: runner (gap, monitor-only guard, statistics)')
    scheduling = 'bus: scheduling (scheduler, polling, jobs)'
    pieces.wrap_methods(polling.PollScheduler, ('run_next', '_begin', '_step'), scheduling)
    pieces.wrap_methods(scheduler.BusScheduler, ('run_once',), scheduling)
    pieces.wrap_methods(jobs.JobQueue, ('expire', 'pop'), scheduling)
    pieces.wrap_methods(deadman.Deadman, ('check',), 'bus: health, deadman, motor state')
    pieces.wrap_methods(health.HealthKeeper, ('answered', 'poll_succeeded', 'poll_failed',
                                              'retry'), 'bus: health, deadman, motor state')
    pieces.wrap_methods(outbox.EventOutbox, ('deliver',), 'bus: hand-off of events')


def bus_on_line(path: str, baudrate: int) -> BusMaster:
    """Return the bus of ``node_cpu.py``'s devices on the paced line at ``path``."""
    config = build_config({**node_bus(path, baudrate), 'devices': list(LINE_DEVICES)},
                          LINE_DEVICES)
    return BusMaster(make_transport(config.link), [device.make_spec() for device in
                                                   config.devices], config.timing)


def run_window(bus: BusMaster, window_s: float) -> Tuple[int, float, float, float]:
    """Run the bus for ``window_s``; return transactions, thread CPU and the window's ends."""
    before = bus.transaction_count()
    started_s, cpu_s = time.monotonic(), time.thread_time()
    while time.monotonic() - started_s < window_s:
        bus.run_step()
    return (bus.transaction_count() - before, time.thread_time() - cpu_s, started_s,
            time.monotonic())


def table(pieces: Pieces, transactions: int, wrapped_us: float,
          unwrapped_us: float) -> List[str]:
    """Return the per-piece lines (us of CPU and calls a transaction) and the totals."""
    rows = sorted(((spent_s / transactions * 1e6, pieces.calls[piece] / transactions, piece)
                   for piece, spent_s in pieces.cpu_s.items()), reverse=True)
    lines = ['       us  calls  piece (a transaction)']
    lines += [f'  {us:7.1f}  {calls:5.2f}  {piece}' for us, calls, piece in rows]
    total_us = sum(row[0] for row in rows)
    lines.append(f'  {total_us:7.1f}         the pieces (wrapped bus: {wrapped_us:.1f}; the '
                 f'rest: outside any piece, or the calls of the wrappers)')
    lines.append(f'  {unwrapped_us:7.1f}         the bus without wrappers (the wrappers cost '
                 f'{wrapped_us - unwrapped_us:.1f})')
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('window_s', nargs='?', type=float, default=10.0)
    parser.add_argument('baudrate', nargs='?', type=int, default=19200)
    arguments = parser.parse_args()
    print(thread_cpu.machine())
    import drive_bridge
    print(f'the bus alone (no ROS), 4 MCD 500 + 4 FC 51 at 100 Hz, {arguments.baudrate} baud '
          f'8E1 timing through the wire pacer; drive_bridge from '
          f'{os.path.dirname(drive_bridge.__file__)}')
    line = PacedSimulator(simulator_devices(LINE_DEVICES), LineTiming(arguments.baudrate, 'E',
                                                                      1))
    bus = None
    try:
        bus = bus_on_line(line.path, arguments.baudrate)
        run_window(bus, WARM_UP_S)
        count, cpu_s, started_s, ended_s = run_window(bus, arguments.window_s)
        bus.shutdown(stop_motors=False)
        wire = line.wire_figures(started_s, ended_s)
        unwrapped_us = cpu_s / count * 1e6
        print(f'without wrappers: {count / (ended_s - started_s):.1f} transactions/s, '
              f'{unwrapped_us:.0f} us of bus thread CPU a transaction, wire '
              f'{wire["fraction"]:.1%}')
        pieces = Pieces()
        install(pieces)  # before the second bus: it keeps bound methods (the hand-off)
        bus = bus_on_line(line.path, arguments.baudrate)
        run_window(bus, WARM_UP_S)
        pieces.cpu_s.clear()
        pieces.calls.clear()
        count, cpu_s, _, _ = run_window(bus, arguments.window_s)
        print('\n'.join(table(pieces, count, cpu_s / count * 1e6, unwrapped_us)))
    finally:
        if bus is not None:
            bus.shutdown(stop_motors=False)
        line.close()
    print(thread_cpu.load())


if __name__ == '__main__':
    sys.exit(main())
