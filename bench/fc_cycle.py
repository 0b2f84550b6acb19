"""
Benchmark: FC 51 cycle time and transactions per cycle at 9600 and 19200 baud, 8E1 timing.

One simulated FC 51, started (so the control word and reference are rewritten every
cycle), in a child process, polled as fast as the bus allows through a wire pacer in this
process (:mod:`drive_bridge.sim.wire_pacer`), not the simulator's own reply pacing: every
byte takes its 8E1 wire time, the line is half duplex and every frame must follow 3.5
characters of silence. Prints the cycle time, the transactions per cycle, the wire-time
minimum of the same frames, and what the pacer's frame log shows: the share of the time the
line carried whole transactions (gaps included), gap violations and collisions.
Run: .venv/bin/python bench/fc_cycle.py [seconds per case]
"""

import math
import sys
import time

from drive_bridge.bus.master import BusMaster, BusTiming, DeviceSpec
from drive_bridge.devices import fc
from drive_bridge.devices.drive import DriveProfile
from drive_bridge.protocol import rtu
from drive_bridge.protocol.requests import (
    ReadCoils, ReadRegisters, WriteCoils, WriteRegister, WriteRegisters)
from drive_bridge.sim.wire_pacer import LineTiming
from drive_bridge.transport.modbus import LinkSettings, PYMODBUS_VERSION, wire_time_s
from drive_bridge.transport.protocols import make_transport
from paced_line import PacedSimulator


def frame_bytes(transaction) -> tuple:
    """Return (request bytes, reply bytes) of one transaction in RTU framing."""
    if isinstance(transaction, WriteCoils):
        return 9 + math.ceil(len(transaction.values) / 8), 8
    if isinstance(transaction, ReadCoils):
        return 8, 5 + math.ceil(transaction.count / 8)
    if isinstance(transaction, ReadRegisters):
        return 8, 5 + 2 * transaction.count
    if isinstance(transaction, WriteRegisters):
        return 9 + 2 * len(transaction.values), 8
    if isinstance(transaction, WriteRegister):
        return 8, 8
    raise TypeError(transaction)


class CountingProfile(DriveProfile):
    """The FC profile, counting the wire time of every planned transaction."""

    def __init__(self, settings: LinkSettings):
        super().__init__(fc.DATA, 'fc51')
        self.settings = settings
        self.wire_s = 0.0
        self.transactions = 0

    def poll(self, control):
        """Run the profile's cycle, counting each step's wire time as it is sent."""
        cycle = super().poll(control)
        try:
            step = next(cycle)
            while True:
                self.wire_s += wire_time_s(self.settings, *frame_bytes(step.request))
                self.transactions += 1
                step = cycle.send((yield step))
        except StopIteration as done:
            return done.value


def bench(baudrate: int, seconds: float, engine: str) -> dict:
    timing = LineTiming(baudrate, 'E', 1)
    line = PacedSimulator(['fc51:1'], timing)
    settings = LinkSettings(port=line.path, baudrate=baudrate, parity='N',
                            timeout_s=0.5)  # the pty takes N (8N2: 11 bits as 8E1)
    wire_settings = LinkSettings(baudrate=baudrate, parity='E')
    profile = CountingProfile(wire_settings)
    readings = []
    bus = BusMaster(make_transport(settings, {'serial_engine': engine}),
                    [DeviceSpec('conv', 1, profile, poll_rate_hz=100.0)],
                    BusTiming(frame_gap_s=rtu.frame_gap_s(baudrate, 'E', 1)),
                    listener=lambda event: readings.append(event.kind == 'reading'))
    deadline = time.monotonic() + 10.0
    while bus.snapshot('conv').reading is None and time.monotonic() < deadline:
        bus.run_once()  # connect, identify, first reading
    started = bus.submit_command('conv', 'start')
    while not started.done() and time.monotonic() < deadline:
        bus.run_once()
    started.result(timeout=0)  # the bench measures a running drive: fail loudly otherwise
    profile.wire_s, profile.transactions, polls_before = 0.0, 0, sum(readings)
    started = time.monotonic()
    while time.monotonic() - started < seconds:
        bus.run_once()
    ended = time.monotonic()
    elapsed = ended - started
    polls = sum(readings) - polls_before
    bus.shutdown(stop_motors=False)
    fraction = line.wire_figures(started, ended)['fraction']
    counters = line.pacer.counters()
    line.close()
    return {'cycle_ms': 1000 * elapsed / polls, 'tx_per_cycle': profile.transactions / polls,
            'wire_ms': 1000 * profile.wire_s / polls, 'polls': polls,
            'log_fraction': fraction,
            'violations': counters.gap_violations, 'collisions': counters.collisions}


def main() -> None:
    seconds = float(sys.argv[1]) if len(sys.argv) > 1 else 5.0
    print(f'pymodbus {PYMODBUS_VERSION}; 1 simulated FC 51 running, 8E1 timing through the '
          f'wire pacer, {seconds:g} s per case')
    print('engine    baud   cycle ms  tx/cycle  wire-time ms/cycle  fraction  cycles/s  '
          'log fraction  gap viol.  collisions')
    for baudrate, engine in ((9600, 'native'), (9600, 'pymodbus'), (19200, 'native'),
                             (19200, 'pymodbus')):
        result = bench(baudrate, seconds, engine)
        print(f'{engine:8s}  {baudrate:5d}  {result["cycle_ms"]:8.1f}  '
              f'{result["tx_per_cycle"]:8.2f}  '
              f'{result["wire_ms"]:18.1f}  {result["wire_ms"] / result["cycle_ms"]:7.1%}  '
              f'{1000 / result["cycle_ms"]:8.1f}  {result["log_fraction"]:12.1%}  '
              f'{result["violations"]:9d}  {result["collisions"]:10d}')


if __name__ == '__main__':
    main()
