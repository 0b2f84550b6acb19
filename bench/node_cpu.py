"""
Benchmark: CPU of drive_bridge_node polling 8 devices at full rate on a paced 19200 line.

4 MCD 500 and 4 FC 51 at 100 Hz on one line paced by the wire pacer at 19200 baud with 8E1
timing (the pty runs 8N2, also 11 bits), ``drive_bridge_node`` in a subprocess. Over a fixed
window the node's CPU time is read from ``/proc/<pid>/stat`` and per thread from
``/proc/<pid>/task/<tid>/stat`` (names from ``comm``; Python threads carry the process's
name; the main thread's id is the process id), printed as % of one core; no subscriber is
matched during the window. The wire fraction achieved is the transactions on the wire
per second (whole request and reply, by the pacer's frame log) over the wire limit of the
same mix of frames (request, reply and two 3.5-character gaps each).
Run: .venv/bin/python bench/node_cpu.py [window seconds] [baud rate, default 19200]
"""

import os
import sys
import time
from typing import Dict, Tuple

from drive_bridge.sim.wire_pacer import LineTiming
from paced_line import (
    LINE_DEVICES, node_bus, NodeProcess, PacedSimulator, ros_environment, simulator_devices,
    wait_for)

ros_environment()
import rclpy  # noqa: E402 - after the environment it reads
from rclpy.qos import DurabilityPolicy, QoSProfile  # noqa: E402
from std_msgs.msg import String  # noqa: E402

BAUDRATE = 19200
WARM_UP_S = 2.0
TICKS_PER_S = os.sysconf('SC_CLK_TCK')


def cpu_split(stat_path: str) -> Tuple[int, int]:
    """Return (utime, stime) of a process or thread, in clock ticks."""
    with open(stat_path) as stream:
        fields = stream.read().rsplit(')', 1)[1].split()
    return int(fields[11]), int(fields[12])  # fields 14 and 15 of proc(5)


def cpu_ticks(stat_path: str) -> int:
    """Return utime + stime of a process or thread, in clock ticks."""
    return sum(cpu_split(stat_path))


def thread_ticks(pid: int) -> Dict[int, Tuple[str, int]]:
    """Return tid -> (name, CPU ticks) for every thread of ``pid``."""
    threads = {}
    for tid in os.listdir(f'/proc/{pid}/task'):
        try:
            with open(f'/proc/{pid}/task/{tid}/comm') as stream:
                name = stream.read().strip()
            threads[int(tid)] = (name, cpu_ticks(f'/proc/{pid}/task/{tid}/stat'))
        except FileNotFoundError:  # the thread ended meanwhile
            continue
    return threads


def wait_until_ready(names) -> None:
    """Wait until every device's latched state is ready, through an rclpy subscriber."""
    node = rclpy.create_node(f'bench_cpu_{os.getpid()}')
    states: Dict[str, str] = {}
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    for name in names:
        node.create_subscription(
            String, f'{name}/state',
            lambda message, name=name: states.__setitem__(name, message.data), latched)
    deadline = time.monotonic() + 60.0
    while not all(states.get(name) == 'ready' for name in names):
        if time.monotonic() > deadline:
            raise RuntimeError(f'devices not ready: {states}')
        rclpy.spin_once(node, timeout_sec=0.05)
    node.destroy_node()


def main() -> None:
    window_s = float(sys.argv[1]) if len(sys.argv) > 1 else 10.0
    baudrate = int(sys.argv[2]) if len(sys.argv) > 2 else BAUDRATE
    timing = LineTiming(baudrate, 'E', 1)
    line = PacedSimulator(simulator_devices(LINE_DEVICES), timing)
    node = NodeProcess(node_bus(line.path, baudrate), LINE_DEVICES)
    rclpy.init()
    try:
        wait_until_ready(list(LINE_DEVICES))
        wait_for(lambda: False, WARM_UP_S)
        started_s = time.monotonic()
        process_before = cpu_split(f'/proc/{node.pid}/stat')
        threads_before = thread_ticks(node.pid)
        time.sleep(window_s)
        process_after = cpu_split(f'/proc/{node.pid}/stat')
        threads_after = thread_ticks(node.pid)
        ended_s = time.monotonic()
        wire = line.wire_figures(started_s, ended_s)
        counters = line.pacer.counters()
    finally:
        rclpy.try_shutdown()
        node.stop()
        line.close()
    seconds = ended_s - started_s

    def percent(ticks: int) -> float:
        return 100.0 * ticks / TICKS_PER_S / seconds

    print(f'drive_bridge_node, 4 MCD 500 + 4 FC 51 at 100 Hz, {baudrate} baud 8E1 timing '
          f'through the wire pacer, {seconds:.1f} s window')
    user, system = (after - before for after, before in zip(process_after, process_before))
    print(f'node CPU: {percent(user + system):.1f} % of one core (user {percent(user):.1f} %, '
          f'system {percent(system):.1f} %)')
    print('  tid      thread            % of one core')
    rows = []
    for tid, (name, ticks) in threads_after.items():
        rows.append((percent(ticks - threads_before.get(tid, (name, 0))[1]), tid, name))
    for share, tid, name in sorted(rows, reverse=True):
        label = f'{name} (main)' if tid == node.pid else name
        print(f'  {tid:<7d}  {label:16s}  {share:5.1f}')
    print(f'wire: {wire["rate"]:.1f} transactions/s of a wire limit of {wire["limit"]:.1f}/s '
          f'for this mix: {wire["fraction"]:.1%}; gap violations {counters.gap_violations}, '
          f'collisions {counters.collisions}')


if __name__ == '__main__':
    main()
