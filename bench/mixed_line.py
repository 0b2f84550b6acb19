"""
Benchmark: the node against a naive per-value loop, same fast data, on the mixed line.

4 MCD 500 and 4 FC 51 on one line paced by the wire pacer (8E1 timing, 11 bits a
character, the 3.5-character gap enforced before every frame), at 9600 and 19200 baud. The
fast data of a device: MCD status, trip, current and temperature (40003-40006); FC 51 status
word, main actual value and motor current (16-14).

- naive: each value read with its own pymodbus request, device after device, sleeping the
  3.5-character gap after each reply (pymodbus does not keep it), in two forms: pymodbus's
  ``ModbusSerialClient`` as it comes (``plain``), and through the bridge's own RTU engine
  (``tuned``: a per-value loop with the framing overhead taken out, so only the number of
  requests differs; the engine keeps the gap itself, so the loop's sleep adds to it);
- node: ``drive_bridge_node`` with every device at ``poll_rate`` 100 (as fast as the line
  allows) and the default ``readout_period`` (1 s), no command in force. Its device polls
  per second are counted in the pacer's frame log (MCD: a read from 40003; FC 51: the read
  of coils 33-64), so they are what crossed the wire.

The ratios are the node's data sets per second over each naive loop's. At the wire limit
the ratio to a per-value loop is bounded by the frames each needs (the FC 51's status and
current sit in separate blocks of its map): printed as "bound", from the requests' wire time
with both gaps (about 2.05x for this line). Also printed: the wire limit for the node's own
mix of frames and the fraction of it the node reached. ``--naive-only`` runs the naive loops
alone, without ROS (for the pymodbus 3.6.9 venv, which has no rclpy).
Run: .venv/bin/python bench/mixed_line.py [window s] [--naive-only]
"""

import inspect
import sys
import time
from typing import Dict, Tuple

from drive_bridge.devices.fc_profile_drive import COIL_STATUS, PROCESS_COILS
from drive_bridge.errors import TransportError
from drive_bridge.protocol import rtu
from drive_bridge.protocol.requests import ReadCoils, ReadRegisters
from drive_bridge.sim.wire_pacer import LineTiming, MASTER, transactions
from drive_bridge.transport.engines import make_transport
from drive_bridge.transport.link import LinkSettings
from paced_line import (
    LINE_DEVICES, node_bus, NodeProcess, PacedSimulator, ros_environment, simulator_devices,
    wait_for)
import pymodbus
from pymodbus.client import ModbusSerialClient
from pymodbus.exceptions import ModbusException

ros_environment()

MCD_FIRST_REGISTER = 2  # 40003
FC_CURRENT_REGISTER = 10 * 1614 - 1  # 16-14
WARM_UP_S = 2.0


def naive_requests(block: Dict) -> Tuple:
    """Return the per-value requests of one device's fast data."""
    if block['family'] == 'mcd':
        return tuple(ReadRegisters(MCD_FIRST_REGISTER + index, 1) for index in range(4))
    return (ReadCoils(COIL_STATUS, 16), ReadCoils(COIL_STATUS + 16, 16),
            ReadRegisters(FC_CURRENT_REGISTER, 2))


def node_requests(block: Dict) -> Tuple:
    """Return the node's requests for the same fast data (no command in force)."""
    if block['family'] == 'mcd':
        return (ReadRegisters(MCD_FIRST_REGISTER, 4),)
    return (ReadCoils(COIL_STATUS, PROCESS_COILS), ReadRegisters(FC_CURRENT_REGISTER, 2))


def ratio_bound(timing: LineTiming) -> float:
    """Return the ratio of a naive loop's wire time to the node's, for one round of the line."""
    def wire_s(requests) -> float:
        return sum(timing.transaction_s(8, request.reply_length()) for request in requests)
    blocks = LINE_DEVICES.values()
    return sum(wire_s(naive_requests(block)) for block in blocks) / \
        sum(wire_s(node_requests(block)) for block in blocks)


class PlainPymodbus:
    """pymodbus's serial client as it comes, one request per call."""

    def __init__(self, line: PacedSimulator):
        self.client = ModbusSerialClient(port=line.path, baudrate=line.timing.baudrate,
                                         bytesize=8, parity='N', stopbits=2, timeout=0.5)
        self.client.connect()
        self.unit = 'device_id' if 'device_id' in inspect.signature(
            self.client.read_coils).parameters else 'slave'

    def execute(self, address: int, request) -> None:
        """Run one read; raise TransportError if it failed."""
        call = self.client.read_coils if isinstance(request, ReadCoils) else \
            self.client.read_holding_registers
        try:
            reply = call(request.address, count=request.count, **{self.unit: address})
        except ModbusException as error:
            raise TransportError(str(error)) from None
        if reply.isError():
            raise TransportError(str(reply))

    def close(self) -> None:
        """Close the port."""
        self.client.close()


def bench_naive(line: PacedSimulator, seconds: float, plain: bool) -> Tuple[float, int]:
    """Run a naive loop; return (device data sets/s, failed requests)."""
    if plain:
        transport = PlainPymodbus(line)
    else:
        transport = make_transport(LinkSettings(port=line.path, baudrate=line.timing.baudrate,
                                                parity='N', timeout_s=0.5))
        transport.connect()
    plan = [(block['address'], naive_requests(block)) for block in LINE_DEVICES.values()]
    sets = failures = 0
    started = time.monotonic()
    while time.monotonic() - started < seconds:
        for address, requests in plan:
            complete = True
            for request in requests:
                try:
                    transport.execute(address, request)
                except TransportError:
                    failures += 1
                    complete = False
                time.sleep(line.timing.gap_s)
            sets += complete
    elapsed = time.monotonic() - started
    transport.close()
    return sets / elapsed, failures


def is_poll_request(data: bytes) -> bool:
    """Return whether a master frame is the status read that each device poll makes once."""
    if len(data) != 8:
        return False
    function, first = data[1], int.from_bytes(data[2:4], 'big')
    return (function == rtu.READ_HOLDING_REGISTERS and first == MCD_FIRST_REGISTER) or \
        (function == rtu.READ_COILS and first == COIL_STATUS)


def bench_node(line: PacedSimulator, seconds: float) -> Dict[str, float]:
    """Run the node on the line; return its device polls/s and its wire figures."""
    from node_cpu import wait_until_ready  # imports rclpy
    node = NodeProcess(node_bus(line.path, line.timing.baudrate), LINE_DEVICES)
    try:
        wait_until_ready(list(LINE_DEVICES))
        wait_for(lambda: False, WARM_UP_S)
        started_s = time.monotonic()
        time.sleep(seconds)
        ended_s = time.monotonic()
    finally:
        node.stop()
    frames = [frame for frame in line.pacer.frames()
              if started_s <= frame.start_s and frame.end_s <= ended_s]
    polls = sum(1 for request, _ in transactions(frames)
                if request.sender == MASTER and is_poll_request(request.data))
    figures = line.wire_figures(started_s, ended_s)
    figures['polls'] = polls / (ended_s - started_s)
    return figures


def main() -> None:
    arguments = [argument for argument in sys.argv[1:] if argument != '--naive-only']
    naive_only = len(arguments) < len(sys.argv) - 1
    seconds = float(arguments[0]) if arguments else 10.0
    print(f'4 MCD 500 + 4 FC 51, fast data only, 8E1 timing through the wire pacer, '
          f'{seconds:g} s per case; pymodbus {pymodbus.__version__} for the naive loop')
    print(' baud  plain sets/s  tuned sets/s' + ('' if naive_only else
          '  node sets/s  ratio plain  ratio tuned  node tx/s  wire limit/s  fraction') +
          '  bound')
    if not naive_only:
        import rclpy
        rclpy.init()
    try:
        for baudrate in (9600, 19200):
            timing = LineTiming(baudrate, 'E', 1)
            line = PacedSimulator(simulator_devices(LINE_DEVICES), timing)
            try:
                plain, plain_failures = bench_naive(line, seconds, plain=True)
                tuned, tuned_failures = bench_naive(line, seconds, plain=False)
                node = None if naive_only else bench_node(line, seconds)
            finally:
                line.close()
            failures = plain_failures + tuned_failures
            node_columns = '' if node is None else (
                f'  {node["polls"]:11.1f}  {node["polls"] / plain:10.2f}x  '
                f'{node["polls"] / tuned:10.2f}x  {node["rate"]:9.1f}  '
                f'{node["limit"]:12.1f}  {node["fraction"]:8.1%}')
            print(f'{baudrate:5d}  {plain:12.1f}  {tuned:12.1f}{node_columns}'
                  f'  {ratio_bound(timing):4.2f}x' +
                  (f'  (naive loops: {failures} failed requests)' if failures else ''))
    finally:
        if not naive_only:
            rclpy.try_shutdown()


if __name__ == '__main__':
    main()
