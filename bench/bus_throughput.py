"""
Benchmark: bus throughput against the wire-time limit at 9600 and 19200 baud, 8E1.

The simulator holds every reply back until the request and the reply would have crossed a
real 8E1 line (3.5-character gaps included), so a pty behaves like a paced wire. Prints
achieved transactions/s as a fraction of the wire limit, and the ratio to a naive loop
that reads each of the six status values with its own pymodbus request.
Both serial engines are measured: the native length-aware RTU engine (the default) and
pymodbus's serial client (``serial_engine: pymodbus``).
Run: .venv/bin/python bench/bus_throughput.py [seconds per case]
"""

import sys
import time

from drive_bridge.bus.master import BusMaster, BusTiming, DeviceSpec
from drive_bridge.devices.mcd import McdProfile
from drive_bridge.protocol import rtu
from drive_bridge.protocol.requests import ReadRegisters
from drive_bridge.sim.mcd_device import make_mcd_server
from drive_bridge.sim.modbus_server import WireTiming
from drive_bridge.transport.modbus import (
    LinkSettings, ModbusTransport, PYMODBUS_VERSION, wire_time_s)
from drive_bridge.transport.protocols import make_transport

UNITS = (20, 21, 22)
REQUEST_BYTES = 8
BATCH_REPLY_BYTES = 5 + 2 * 6
SINGLE_REPLY_BYTES = 5 + 2


def wire_limit_per_s(baudrate: int, reply_bytes: int) -> float:
    """Return transactions/s a perfect master could reach on an 8E1 line."""
    return 1.0 / wire_time_s(LinkSettings(baudrate=baudrate, parity='E'), REQUEST_BYTES,
                             reply_bytes)


def start_server(baudrate: int):
    server = make_mcd_server(dict.fromkeys(UNITS, 'mcd500'),
                             wire=WireTiming(baudrate, 'E', 1))
    server.open_pty()
    server.start()
    return server


def bench_bus(baudrate: int, seconds: float, engine: str) -> tuple:
    """Poll three devices as fast as the bus allows; return (transactions/s, values/s)."""
    server = start_server(baudrate)
    settings = LinkSettings(port=server.pty_path, baudrate=baudrate, parity='N',
                            timeout_s=0.5)  # the pty takes N; the wire timing is 8E1
    gap_s = rtu.frame_gap_s(baudrate, 'E', 1)
    specs = [DeviceSpec(f'd{unit}', unit, McdProfile('mcd500'), poll_rate_hz=100.0)
             for unit in UNITS]
    bus = BusMaster(make_transport(settings, {'serial_engine': engine}), specs,
                    BusTiming(frame_gap_s=gap_s))
    bus.run_once()  # connect
    for _ in range(6):  # warm up
        bus.run_once()
    before = sum(int(bus.snapshot(f'd{u}').stats['transactions']) for u in UNITS)
    started = time.monotonic()
    while time.monotonic() - started < seconds:
        bus.run_once()
    elapsed = time.monotonic() - started
    after = sum(int(bus.snapshot(f'd{u}').stats['transactions']) for u in UNITS)
    bus.shutdown(stop_motors=False)
    server.stop()
    rate = (after - before) / elapsed
    return rate, rate * 6


def bench_naive(baudrate: int, seconds: float) -> float:
    """Read each of the six values with its own pymodbus request; return values/s."""
    server = start_server(baudrate)
    transport = ModbusTransport(LinkSettings(port=server.pty_path, baudrate=baudrate,
                                             parity='N', timeout_s=0.5))
    transport.connect()
    values = 0
    started = time.monotonic()
    while time.monotonic() - started < seconds:
        for unit in UNITS:
            for address in range(2, 8):
                transport.execute(unit, ReadRegisters(address, 1))
                values += 1
    elapsed = time.monotonic() - started
    transport.close()
    server.stop()
    return values / elapsed


def main() -> None:
    seconds = float(sys.argv[1]) if len(sys.argv) > 1 else 5.0
    print(f'pymodbus {PYMODBUS_VERSION}; 3 simulated MCD 500, 6 registers per poll, 8E1 wire')
    print('engine    baud   bus tx/s  wire limit  fraction  values/s  naive values/s  ratio')
    for baudrate in (9600, 19200):
        naive = bench_naive(baudrate, seconds)
        limit = wire_limit_per_s(baudrate, BATCH_REPLY_BYTES)
        for engine in ('native', 'pymodbus'):
            rate, values = bench_bus(baudrate, seconds, engine)
            print(f'{engine:8s}  {baudrate:5d}  {rate:8.1f}  {limit:10.1f}  {rate / limit:7.1%}'
                  f'  {values:8.0f}  {naive:14.0f}  {values / naive:5.2f}x')


if __name__ == '__main__':
    main()
