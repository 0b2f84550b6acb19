"""
Benchmark: trigger-to-wire latency of a command through the real node under full polling.

4 MCD 500 and 4 FC 51 on one line paced by the wire pacer at 9600 and 19200 baud with 8E1
timing (the pty runs 8N2, also 11 bits a character), each polled at 100 Hz by
``drive_bridge_node`` in a subprocess. An rclpy client in this process calls ``<dev>/start``
and ``<dev>/stop`` in turn, device after device, each after a random pause of up to 0.5 s
(several device polls, so that calls land at every phase of the poll cycle rather than just
after the poll that follows a command). Latency = from the moment the service request is
sent to the moment the command frame starts on the wire, by the pacer's frame log; the pacer
and the client share this process's monotonic clock. The command frame is recognised by its
bytes (the MCD's write of 40002; the FC's control word write carrying the new word, which differs
from the keepalive before it). Prints p50, p99 and the largest latency, the wire time of one
MCD status read (8 + 17 bytes and two gaps) and of each command transaction.
Run: .venv/bin/python bench/command_latency.py [calls per baud rate]
"""

import os
import random
import statistics
import sys
import time
from typing import Dict, Optional, Tuple

from drive_bridge.devices import fc51, mcd
from drive_bridge.devices.fc_profile_drive import FcProfileModbusDrive
from drive_bridge.protocol import fc_profile, rtu
from drive_bridge.protocol.commands import Command
from drive_bridge.sim.wire_pacer import LineTiming, MASTER
from paced_line import (
    LINE_DEVICES, node_bus, NodeProcess, PacedSimulator, ros_environment, simulator_devices)

ros_environment()
import rclpy  # noqa: E402 - after the environment it reads
from rclpy.qos import DurabilityPolicy, QoSProfile  # noqa: E402
from std_msgs.msg import String  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
COMMANDS = ('start', 'stop')
MAX_PAUSE_S = 0.5
SEED = 1


def command_frame(block: Dict, command: str) -> bytes:
    """Return the bytes of the request that carries ``command`` to the device of ``block``."""
    unit = block['address']
    typed = Command(command)
    if block['family'] == 'mcd':
        return rtu.write_register_request(unit, mcd.REGISTER['command'].address,
                                          mcd.COMMAND_VALUES[typed]).encode()
    write = FcProfileModbusDrive(fc51.DATA, block['model']).process_write(
        fc_profile.COMMAND_WORDS[typed], 0)  # speed_reference 0: reference word 0
    return write.frame(unit).encode()


class CommandClient:
    """An rclpy node that watches the devices' states and calls their command services."""

    def __init__(self, names):
        self.node = rclpy.create_node(f'bench_client_{os.getpid()}')
        self.states: Dict[str, str] = {}
        for name in names:
            self.node.create_subscription(
                String, f'{name}/state',
                lambda message, name=name: self.states.__setitem__(name, message.data), LATCHED)
        self.clients = {(name, command): self.node.create_client(Trigger, f'{name}/{command}')
                        for name in names for command in COMMANDS}

    def spin_until(self, predicate, timeout_s: float) -> bool:
        deadline = time.monotonic() + timeout_s
        while not predicate():
            if time.monotonic() > deadline:
                return False
            rclpy.spin_once(self.node, timeout_sec=0.05)
        return True

    def call(self, name: str, command: str, timeout_s: float = 5.0) -> Tuple[float, bool]:
        """Call ``<name>/<command>``; return (when the request was sent, whether it succeeded)."""
        client = self.clients[(name, command)]
        if not client.wait_for_service(timeout_sec=timeout_s):
            raise RuntimeError(f'no service {name}/{command}')
        sent_s = time.monotonic()
        future = client.call_async(Trigger.Request())
        rclpy.spin_until_future_complete(self.node, future, timeout_sec=timeout_s)
        return sent_s, bool(future.done() and future.result().success)

    def close(self) -> None:
        self.node.destroy_node()


def frame_start(line: PacedSimulator, data: bytes, after_s: float) -> Optional[float]:
    """Return when the first master frame ``data`` started on the wire after ``after_s``."""
    for frame in line.pacer.frames():
        if frame.sender == MASTER and frame.start_s >= after_s and frame.data == data:
            return frame.start_s
    return None


def bench(baudrate: int, calls: int) -> dict:
    timing = LineTiming(baudrate, 'E', 1)
    line = PacedSimulator(simulator_devices(LINE_DEVICES), timing)
    node = NodeProcess(node_bus(line.path, baudrate), LINE_DEVICES)
    client = CommandClient(list(LINE_DEVICES))
    random_pause = random.Random(SEED)
    latencies, missing, refused = [], 0, 0
    try:
        if not client.spin_until(lambda: all(client.states.get(name) == 'ready'
                                             for name in LINE_DEVICES), 60.0):
            raise RuntimeError(f'devices not ready: {client.states}\n{node.output()}')
        client.spin_until(lambda: False, 1.0)  # full polling for a second first
        names = list(LINE_DEVICES)
        for index in range(calls):
            name = names[index % len(names)]
            command = COMMANDS[(index // len(names)) % 2]
            sent_s, success = client.call(name, command)
            refused += not success
            started_s = frame_start(line, command_frame(LINE_DEVICES[name], command), sent_s)
            if started_s is None:
                missing += 1
            else:
                latencies.append(started_s - sent_s)
            client.spin_until(lambda: False, random_pause.uniform(0.0, MAX_PAUSE_S))
        counters = line.pacer.counters()
    finally:
        client.close()
        node.stop()
        line.close()
    return {'latencies': latencies, 'missing': missing, 'refused': refused,
            'violations': counters.gap_violations, 'collisions': counters.collisions,
            'timing': timing}


def main() -> None:
    calls = int(sys.argv[1]) if len(sys.argv) > 1 else 200
    rclpy.init()
    try:
        print(f'4 MCD 500 + 4 FC 51 at 100 Hz through drive_bridge_node; 8E1 timing through '
              f'the wire pacer; {calls} start/stop calls per baud rate')
        print('baud   calls  p50 ms  p99 ms  max ms  one MCD read ms  MCD command ms  '
              'FC command ms  no frame  refused  gap viol.  collisions')
        for baudrate in (9600, 19200):
            result = bench(baudrate, calls)
            timing = result['timing']
            latencies = [1000 * value for value in result['latencies']]
            percentiles = statistics.quantiles(latencies, n=100, method='inclusive')
            print(f'{baudrate:5d}  {len(latencies):5d}  {statistics.median(latencies):6.1f}  '
                  f'{percentiles[98]:6.1f}  {max(latencies):6.1f}  '
                  f'{1000 * timing.transaction_s(8, 17):15.1f}  '
                  f'{1000 * timing.transaction_s(8, 8):14.1f}  '
                  f'{1000 * timing.transaction_s(13, 8):13.1f}  {result["missing"]:8d}  '
                  f'{result["refused"]:7d}  {result["violations"]:9d}  '
                  f'{result["collisions"]:10d}')
    finally:
        rclpy.try_shutdown()


if __name__ == '__main__':
    main()
