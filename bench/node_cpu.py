"""
Benchmark: CPU of drive_bridge_node polling 8 devices at full rate on a paced 19200 line.

4 MCD 500 and 4 FC 51 at 100 Hz on one line paced by the wire pacer at 19200 baud with 8E1
timing (the pty runs 8N2, also 11 bits), ``drive_bridge_node`` in a subprocess. Over a fixed
window the node's CPU time is read from ``/proc/<pid>/stat`` and per thread from
``/proc/<pid>/task/<tid>/stat`` (names from ``comm``; Python threads carry the process's
name; the main thread's id is the process id), printed as % of one core. By default no
subscriber is matched during the window (the node then skips its volatile topics); with
``--listen`` a child process subscribes to every topic of every device and to
``/diagnostics`` during the window, as a bag recorder or Foxglove would, and the messages
it received are printed. The wire fraction achieved is the transactions on the wire per
second (whole request and reply, by the pacer's frame log) over the wire limit of the same
mix of frames (request, reply and two 3.5-character gaps each).
Run: .venv/bin/python bench/node_cpu.py [window seconds] [baud rate, default 19200] [--listen]
"""

import argparse
import os
import signal
import subprocess
import sys
import time
from typing import Dict, List, Tuple

from drive_bridge.sim.wire_pacer import LineTiming
from paced_line import (
    LINE_DEVICES, node_bus, NodeProcess, PacedSimulator, ros_environment, simulator_devices,
    wait_for)

ros_environment()
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402, I100 - after the environment
import rclpy  # noqa: E402
from rclpy.qos import DurabilityPolicy, QoSProfile  # noqa: E402
from std_msgs.msg import Float32, String, UInt16, UInt32  # noqa: E402

# Every topic a device may have and its type, as the node publishes them (ros/publishers.py).
DEVICE_TOPICS = {'state': String, 'trip': String, 'status_word': UInt16, 'trip_code': UInt16,
                 'motor_current': Float32, 'motor_temperature': Float32,
                 'speed_feedback': Float32, 'alarm_word': UInt32, 'warning_word': UInt32}

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


def listen(names: List[str]) -> None:
    """Subscribe to every topic of ``names`` and /diagnostics until SIGTERM; print the count."""
    signal.signal(signal.SIGTERM, lambda *_: rclpy.try_shutdown())
    rclpy.init()
    node = rclpy.create_node(f'bench_listener_{os.getpid()}')
    received = [0]

    def count(_message) -> None:
        received[0] += 1
    for name in names:
        for topic, kind in DEVICE_TOPICS.items():
            node.create_subscription(kind, f'{name}/{topic}', count, 10)
    node.create_subscription(DiagnosticArray, '/diagnostics', count, 10)
    print('listening', flush=True)
    try:
        while rclpy.ok():
            rclpy.spin_once(node, timeout_sec=0.5)
    except Exception:  # noqa: B902 - the context shut down under spin_once
        pass
    print(f'received {received[0]}', flush=True)


def start_listener(names: List[str]) -> subprocess.Popen:
    """Start :func:`listen` in a child process; return once it has subscribed."""
    child = subprocess.Popen([sys.executable, os.path.abspath(__file__), '--listener-child',
                              *names], stdout=subprocess.PIPE, text=True)
    if child.stdout.readline().strip() != 'listening':
        raise RuntimeError('the listener did not start')
    return child


def stop_listener(child: subprocess.Popen) -> str:
    """Stop the listener; return what it said it received."""
    child.send_signal(signal.SIGTERM)
    output, _ = child.communicate(timeout=15)
    return output.strip()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('window_s', nargs='?', type=float, default=10.0)
    parser.add_argument('baudrate', nargs='?', type=int, default=BAUDRATE)
    parser.add_argument('--listen', action='store_true',
                        help='subscribe to every topic during the window (a child process)')
    parser.add_argument('--listener-child', nargs='*', help=argparse.SUPPRESS)
    arguments = parser.parse_args()
    if arguments.listener_child is not None:
        listen(arguments.listener_child)
        return
    window_s, baudrate = arguments.window_s, arguments.baudrate
    timing = LineTiming(baudrate, 'E', 1)
    line = PacedSimulator(simulator_devices(LINE_DEVICES), timing)
    node = NodeProcess(node_bus(line.path, baudrate), LINE_DEVICES)
    listener = None
    rclpy.init()
    try:
        wait_until_ready(list(LINE_DEVICES))
        if arguments.listen:
            listener = start_listener(list(LINE_DEVICES))
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
        heard = stop_listener(listener) if listener is not None else ''
        rclpy.try_shutdown()
        node.stop()
        line.close()
    seconds = ended_s - started_s

    def percent(ticks: int) -> float:
        return 100.0 * ticks / TICKS_PER_S / seconds

    print(f'drive_bridge_node, 4 MCD 500 + 4 FC 51 at 100 Hz, {baudrate} baud 8E1 timing '
          f'through the wire pacer, {seconds:.1f} s window, ' +
          (f'every topic subscribed (the listener {heard} messages)' if arguments.listen
           else 'no subscriber'))
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
