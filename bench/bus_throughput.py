"""
Benchmark: bus throughput against the wire-time limit at 9600 and 19200 baud, 8E1 timing.

The master talks to the simulator (a child process) through a wire pacer in this process
(:mod:`drive_bridge.sim.wire_pacer`), not the simulator's own reply pacing: every byte takes
its 8E1 wire time (11 bits), the line is half duplex, and a frame that does not follow 3.5
characters of silence is not recognised, so a master can lose throughput on the wire but
never gain it. The pty itself runs 8N2.
Prints the bus's achieved transactions/s as a fraction of the wire limit (from the master's
count and from the pacer's frame log), gap violations and collisions, the bus thread's CPU
and wake-ups a transaction, and the ratio to a naive loop that reads each of the six status
values with its own request through pymodbus's serial client and sleeps the gap after each
reply itself (pymodbus does not keep it: without the sleep every second request is glued to
the reply before it and lost). The bus keeps the gap whatever it is given: the line
discipline waits the inter-frame silence after every reply (``frame_gap_s`` 0 is the second
row).
Run: .venv/bin/python bench/bus_throughput.py [seconds per case]
"""

import sys
import time

from drive_bridge.bus.master import BusMaster, BusTiming, DeviceSpec
from drive_bridge.devices.mcd import McdProfile
from drive_bridge.sim.wire_pacer import LineTiming
from drive_bridge.transport.engines import make_transport
from drive_bridge.transport.link import LinkSettings
from paced_line import PacedSimulator
import pymodbus
from pymodbus.client import ModbusSerialClient

UNITS = (20, 21, 22)
REQUEST_BYTES = 8
BATCH_REPLY_BYTES = 5 + 2 * 6


def open_line(baudrate: int) -> PacedSimulator:
    """Start three simulated MCD 500 behind a pacer with 8E1 timing."""
    return PacedSimulator([f'mcd500:{unit}' for unit in UNITS], LineTiming(baudrate, 'E', 1))


def master_settings(line: PacedSimulator) -> LinkSettings:
    """Return the master's link: the pty takes parity N (8N2: 11 bits as 8E1)."""
    return LinkSettings(port=line.path, baudrate=line.timing.baudrate, parity='N',
                        timeout_s=0.5)


def wire_limit_per_s(timing: LineTiming, reply_bytes: int) -> float:
    """Return transactions/s a perfect master could reach (request, reply, two gaps)."""
    return 1.0 / timing.transaction_s(REQUEST_BYTES, reply_bytes)


def bench_bus(baudrate: int, seconds: float, keep_gap: bool = True) -> dict:
    """Poll three devices as fast as the bus allows; return the master's and the wire's rate."""
    line = open_line(baudrate)
    gap_s = line.timing.gap_s if keep_gap else 0.0
    specs = [DeviceSpec(f'd{unit}', unit, McdProfile('mcd500'), poll_rate_hz=100.0)
             for unit in UNITS]
    bus = BusMaster(make_transport(master_settings(line)), specs,
                    BusTiming(frame_gap_s=gap_s, offline_after=1000))
    bus.run_once()  # connect
    for _ in range(6):  # warm up
        bus.run_step()
    before = bus.transaction_count() - errors(bus)
    waits = WaitCounter()
    started, cpu_before = time.monotonic(), time.thread_time()
    with waits:
        while time.monotonic() - started < seconds:
            bus.run_step()
    ended, cpu_s = time.monotonic(), time.thread_time() - cpu_before
    done = bus.transaction_count() - errors(bus) - before
    bus.shutdown(stop_motors=False)
    figures = line.wire_figures(started, ended)
    counters = line.pacer.counters()
    line.close()
    return {'rate': done / (ended - started), 'log_fraction': figures['fraction'],
            'violations': counters.gap_violations, 'collisions': counters.collisions,
            'cpu_us': 1e6 * cpu_s / max(1, done), 'waits': waits.count / max(1, done)}


class WaitCounter:
    """Count the bus thread's wake-ups while entered: blocking selects and sleeps."""

    def __init__(self):
        self.count = 0
        self._originals = ()

    def __enter__(self) -> 'WaitCounter':
        import select
        import threading
        original_select, original_sleep = select.select, time.sleep
        bus_thread = threading.current_thread()  # the pacer's thread is not counted

        def counting_select(*args):
            if threading.current_thread() is bus_thread and args[3:] and args[3]:
                self.count += 1  # a zero timeout does not sleep
            return original_select(*args)

        def counting_sleep(seconds):
            self.count += threading.current_thread() is bus_thread
            return original_sleep(seconds)
        select.select, time.sleep = counting_select, counting_sleep
        self._originals = (original_select, original_sleep)
        return self

    def __exit__(self, *exc) -> None:
        import select
        select.select, time.sleep = self._originals


def errors(bus: BusMaster) -> int:
    """Return the failed transactions of every device."""
    return sum(int(bus.snapshot(f'd{unit}').stats['errors']) for unit in UNITS)


def bench_naive(baudrate: int, seconds: float) -> tuple:
    """Read each of the six values with its own pymodbus request; return (values/s, errors)."""
    line = open_line(baudrate)
    client = ModbusSerialClient(port=line.path, baudrate=baudrate, parity='N', stopbits=2,
                                timeout=0.5, retries=0)
    keyword = 'device_id' if pymodbus.__version__ >= '3.10' else 'slave'
    client.connect()
    values = failures = 0
    started = time.monotonic()
    while time.monotonic() - started < seconds:
        for unit in UNITS:
            for address in range(2, 8):
                try:
                    reply = client.read_holding_registers(address, count=1, **{keyword: unit})
                    failed = reply.isError()
                except Exception:  # noqa: B902 - pymodbus raises its own and OS errors
                    failed = True
                values += not failed
                failures += failed
                time.sleep(line.timing.gap_s)
    elapsed = time.monotonic() - started
    client.close()
    line.close()
    return values / elapsed, failures


def main() -> None:
    seconds = float(sys.argv[1]) if len(sys.argv) > 1 else 5.0
    print(f'pymodbus {pymodbus.__version__} (the naive loop); 3 simulated MCD 500, 6 registers '
          f'per poll, 8E1 timing through the wire pacer, {seconds:g} s per case')
    print('bus            baud  master tx/s  wire limit  fraction  log fraction  gap viol.  '
          'collisions  values/s  naive values/s  ratio  CPU us/tx  waits/tx')
    for baudrate in (9600, 19200):
        naive, naive_failures = bench_naive(baudrate, seconds)
        limit = wire_limit_per_s(LineTiming(baudrate, 'E', 1), BATCH_REPLY_BYTES)
        for keep_gap in (True, False):
            result = bench_bus(baudrate, seconds, keep_gap)
            label = 'gap kept' if keep_gap else 'gap 0 given'
            values = result['rate'] * 6
            print(f'{label:13s}  {baudrate:5d}  {result["rate"]:11.1f}  {limit:10.1f}  '
                  f'{result["rate"] / limit:8.1%}  {result["log_fraction"]:12.1%}  '
                  f'{result["violations"]:9d}  {result["collisions"]:10d}  {values:8.0f}  '
                  f'{naive:14.0f}  {values / naive:5.2f}x  {result["cpu_us"]:9.0f}  '
                  f'{result["waits"]:8.1f}')
        if naive_failures:
            print(f'  (the naive loop at {baudrate} lost {naive_failures} requests)')


if __name__ == '__main__':
    main()
