"""
Benchmark: ``~/joint_states`` messages per second per drive, by line, through the node.

1, 2, 4 and 8 FC 51 drives on one line paced by the wire pacer (8E1 timing, 11 bits a
character; the Modbus RTU silence of 3.5 characters, the FC protocol's of 2) at 38400 and
115200 baud, over Modbus RTU and over the FC protocol. Every drive is a joint, started
(running: over Modbus its control word and reference are written every poll, as on a wheel
base) and polled as fast as the line allows (``poll_rate`` 100, the highest the node
takes). A subscriber in this process counts each joint's ``~/joint_states`` messages
(reliable, as ``ros2 topic hz`` or a recorder would) over a fixed window; the table gives
the mean per drive and the lowest drive's, the bus transactions per second and the wire
fraction (the pacer's frame log), and the node's CPU (``thread_cpu.py``).
Run: .venv/bin/python bench/joint_rates.py [window s] [--protocols modbus_rtu fc_protocol]
[--bauds 38400 115200] [--drives 1 2 4 8]
"""

import argparse
import os
import time
from typing import Dict, List

from drive_bridge.protocol import fc_telegram
from drive_bridge.sim.wire_pacer import LineTiming, MODBUS_GAP_CHARACTERS
from joint_cpu import devices, start_drives
from node_cpu import wait_until_ready
from paced_line import (
    conditions, node_bus, NodeProcess, PacedSimulator, ros_environment, simulator_devices)
import thread_cpu

ros_environment()
import rclpy  # noqa: E402, I100 - after the environment it reads
from rclpy.qos import QoSProfile, ReliabilityPolicy  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

WARM_UP_S = 2.0
GAPS = {'modbus_rtu': MODBUS_GAP_CHARACTERS, 'fc_protocol': fc_telegram.GAP_CHARACTERS}
SIMULATOR_PROTOCOLS = {'modbus_rtu': 'modbus', 'fc_protocol': 'fc_protocol'}


class StateCounter:
    """Count ``~/joint_states`` messages by joint."""

    def __init__(self):
        self.node = rclpy.create_node(f'bench_rates_{os.getpid()}')
        self.counts: Dict[str, int] = {}
        self.node.create_subscription(
            JointState, '/drive_bridge/joint_states', self._count,
            QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE))

    def _count(self, message: JointState) -> None:
        for name in message.name:
            self.counts[name] = self.counts.get(name, 0) + 1

    def spin_for(self, seconds: float) -> None:
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            rclpy.spin_once(self.node, timeout_sec=0.05)

    def close(self) -> None:
        self.node.destroy_node()


def measure(protocol: str, baudrate: int, count: int, window_s: float) -> Dict:
    """Run ``count`` started FC 51 joints on one line; return the rates."""
    blocks = devices(True, count)
    timing = LineTiming(baudrate, 'E', 1, gap_characters=GAPS[protocol])
    line = PacedSimulator(simulator_devices(blocks), timing,
                          protocol=SIMULATOR_PROTOCOLS[protocol])
    node = NodeProcess({**node_bus(line.path, baudrate), 'protocol': protocol}, blocks)
    counter = StateCounter()
    try:
        wait_until_ready(list(blocks))
        start_drives(list(blocks))
        counter.spin_for(WARM_UP_S)
        counts_before = dict(counter.counts)
        cpu_before = thread_cpu.sample(node.pid)
        started_s = time.monotonic()
        counter.spin_for(window_s)
        ended_s = time.monotonic()
        cpu_after = thread_cpu.sample(node.pid)
        counts_after = dict(counter.counts)
        wire = line.wire_figures(started_s, ended_s)
    finally:
        counter.close()
        node.stop()
        line.close()
    seconds = ended_s - started_s
    rates = [(counts_after.get(name, 0) - counts_before.get(name, 0)) / seconds
             for name in blocks]
    rows = thread_cpu.shares(cpu_before, cpu_after, seconds, {})
    return {'mean': sum(rates) / len(rates), 'lowest': min(rates), 'tx': wire['rate'],
            'fraction': wire['fraction'], 'cpu': thread_cpu.total_pct(rows)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('window_s', nargs='?', type=float, default=10.0)
    parser.add_argument('--protocols', nargs='+', default=['modbus_rtu', 'fc_protocol'],
                        choices=sorted(GAPS))
    parser.add_argument('--bauds', nargs='+', type=int, default=[38400, 115200])
    parser.add_argument('--drives', nargs='+', type=int, default=[1, 2, 4, 8])
    arguments = parser.parse_args()
    print(thread_cpu.machine())
    print(f'FC 51 joints, started, poll_rate 100, through drive_bridge_node on a line paced by '
          f'the wire pacer (8E1 timing), {arguments.window_s:g} s windows; {conditions()}')
    print('| protocol | baud | drives | joint_states/s per drive (lowest) | bus tx/s | '
          'wire fraction | node CPU, % of one core |')
    print('| --- | --- | --- | --- | --- | --- | --- |')
    rclpy.init()
    results: List[Dict] = []
    try:
        for protocol in arguments.protocols:
            for baudrate in arguments.bauds:
                for count in arguments.drives:
                    result = measure(protocol, baudrate, count, arguments.window_s)
                    results.append(result)
                    print(f'| {protocol} | {baudrate} | {count} | {result["mean"]:.1f} '
                          f'({result["lowest"]:.1f}) | {result["tx"]:.1f} | '
                          f'{result["fraction"]:.1%} | {result["cpu"]:.1f} |', flush=True)
    finally:
        rclpy.try_shutdown()
    print(thread_cpu.load())


if __name__ == '__main__':
    main()
