"""
Benchmark: CPU of drive_bridge_node polling 8 devices at full rate on a paced 19200 line.

4 MCD 500 and 4 FC 51 at 100 Hz on one line paced by the wire pacer at 19200 baud with 8E1
timing (the pty runs 8N2, also 11 bits), ``drive_bridge_node`` in a subprocess. Over a fixed
window the node's CPU is read per thread from the scheduler's own accounting
(``/proc/<pid>/task/<tid>/schedstat`` and ``sched``, see ``thread_cpu.py``), printed as %
of one core with each thread's wake-ups a second, and the bus thread's wake-ups and CPU per
transaction. By default no subscriber is matched during the window (the node then skips its
volatile topics and ``/diagnostics``); with ``--listen`` a child process subscribes to
every topic of every device and to ``/diagnostics`` during the window, as a bag recorder or
Foxglove would, and the messages it received are printed (``--listen status_word``: only
the topics named, of every device); with ``--calls N`` another child process calls N
``std_srvs/Trigger`` services a second (``stop`` of each MCD 500 in turn, which are
stopped: each call is one write on the bus and an answer), and the calls answered are
printed. The wire fraction achieved is the transactions on the wire per second (whole
request and reply, by the pacer's frame log) over the wire limit of the same mix of frames
(request, reply and two 3.5-character gaps each). ``--runs`` repeats the measurement with
a new node and line each time. The machine and its load are printed first and last.
Run: .venv/bin/python bench/node_cpu.py [window seconds] [baud rate, default 19200]
[--listen [TOPIC,...]] [--calls 4] [--runs 3]
"""

import argparse
import os
import signal
import statistics
import subprocess
import sys
import time
from typing import Dict, List

from drive_bridge.sim.wire_pacer import LineTiming
from paced_line import (
    conditions, LINE_DEVICES, node_bus, NodeProcess, PacedSimulator, ros_environment,
    simulator_devices, versions, wait_for)
import thread_cpu

ros_environment()
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402, I100 - after the environment
import rclpy  # noqa: E402
from rclpy.qos import DurabilityPolicy, QoSProfile  # noqa: E402
from std_msgs.msg import Float32, String, UInt16, UInt32  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

# Every topic a device may have and its type, as the node publishes them (ros/node/publishers.py).
DEVICE_TOPICS = {'state': String, 'trip': String, 'status_word': UInt16, 'trip_code': UInt16,
                 'motor_current': Float32, 'motor_temperature': Float32,
                 'speed_feedback': Float32, 'alarm_word': UInt32, 'warning_word': UInt32}
BUS_THREAD = 'drive-bridge-bus'
BAUDRATE = 19200
WARM_UP_S = 2.0


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


def listen(arguments: List[str]) -> None:
    """
    Subscribe to the devices' topics until SIGTERM; print the count.

    ``arguments``: the topics, comma-separated (``all``: every topic of each device and
    /diagnostics), then the device names.
    """
    topics, names = arguments[0].split(','), arguments[1:]
    every = topics == ['all']
    signal.signal(signal.SIGTERM, lambda *_: rclpy.try_shutdown())
    rclpy.init()
    node = rclpy.create_node(f'bench_listener_{os.getpid()}')
    received = [0]

    def count(_message) -> None:
        received[0] += 1
    for name in names:
        for topic, kind in DEVICE_TOPICS.items():
            if every or topic in topics:
                node.create_subscription(kind, f'{name}/{topic}', count, 10)
    if every:
        node.create_subscription(DiagnosticArray, '/diagnostics', count, 10)
    print('listening', flush=True)
    spin_until_shutdown(node)
    print(f'received {received[0]}', flush=True)


def spin_until_shutdown(node) -> None:
    """Spin ``node`` until SIGTERM shuts rclpy down (the child processes' main loop)."""
    try:
        while rclpy.ok():
            rclpy.spin_once(node, timeout_sec=0.5)
    except Exception:  # noqa: B902 - the context shut down under spin_once
        pass


def call_triggers(rate_hz: float, names: List[str]) -> None:
    """Call ``<name>/stop`` of ``names`` in turn, ``rate_hz`` a second, until SIGTERM."""
    signal.signal(signal.SIGTERM, lambda *_: rclpy.try_shutdown())
    rclpy.init()
    node = rclpy.create_node(f'bench_caller_{os.getpid()}')
    clients = [node.create_client(Trigger, f'{name}/stop') for name in names]
    for client in clients:
        client.wait_for_service(timeout_sec=30.0)
    counts = {'sent': 0, 'answered': 0, 'succeeded': 0}

    def answered(future) -> None:
        counts['answered'] += 1
        counts['succeeded'] += bool(future.result() and future.result().success)

    def call() -> None:
        future = clients[counts['sent'] % len(clients)].call_async(Trigger.Request())
        future.add_done_callback(answered)
        counts['sent'] += 1
    node.create_timer(1.0 / rate_hz, call)
    print('calling', flush=True)
    spin_until_shutdown(node)
    print(f'sent {counts["sent"]}, answered {counts["answered"]}, succeeded '
          f'{counts["succeeded"]}', flush=True)


def start_child(*arguments: str, ready: str) -> subprocess.Popen:
    """Start this file as a child process with ``arguments``; return once it says ``ready``."""
    child = subprocess.Popen([sys.executable, os.path.abspath(__file__), *arguments],
                             stdout=subprocess.PIPE, text=True)
    if child.stdout.readline().strip() != ready:
        raise RuntimeError(f'the child {arguments[0]} did not start')
    return child


def stop_child(child: subprocess.Popen) -> str:
    """Stop a child started by :func:`start_child`; return its last line."""
    child.send_signal(signal.SIGTERM)
    output, _ = child.communicate(timeout=15)
    return output.strip()


def measure(window_s: float, baudrate: int, listen: List[str], calls_hz: float,
            source: str = '') -> Dict:
    """Run the node (from ``source``: see NodeProcess) on a fresh line for one window."""
    timing = LineTiming(baudrate, 'E', 1)
    line = PacedSimulator(simulator_devices(LINE_DEVICES), timing)
    node = NodeProcess(node_bus(line.path, baudrate), LINE_DEVICES, source=source)
    children: Dict[str, subprocess.Popen] = {}
    said: Dict[str, str] = {}
    try:
        wait_until_ready(list(LINE_DEVICES))
        if listen:
            children['listener'] = start_child('--listener-child', ','.join(listen),
                                               *LINE_DEVICES, ready='listening')
        if calls_hz:
            mcds = [name for name, block in LINE_DEVICES.items() if block['family'] == 'mcd']
            children['caller'] = start_child('--caller-child', str(calls_hz), *mcds,
                                             ready='calling')
        wait_for(lambda: False, WARM_UP_S)
        names = thread_cpu.python_thread_names(node.pid)
        window = thread_cpu.measure_window(node.pid, window_s)
        wire = line.wire_figures(window.started_s, window.ended_s)
        requests = line.requests(window.started_s, window.ended_s)
        counters = line.pacer.counters()
    finally:
        for label, child in children.items():
            said[label] = stop_child(child)
        node.stop()
        line.close()
    seconds = window.seconds
    rows = window.shares(names)
    bus = [row for row in rows if row.name == BUS_THREAD] or rows[:1]
    return {'rows': rows, 'pid': node.pid, 'seconds': seconds, 'wire': wire,
            'counters': counters, 'said': said, 'bus': bus[0], 'requests': requests,
            'total': thread_cpu.total_pct(rows)}


def print_run(result: Dict, index: int, label: str) -> None:
    """Print one run's figures."""
    seconds, wire, bus = result['seconds'], result['wire'], result['bus']
    said = '; '.join(f'{who}: {text}' for who, text in result['said'].items())
    print(f'run {index + 1}{" of " + label if label else ""}: {seconds:.1f} s window' +
          (f' ({said})' if said else ''))
    print(f'node CPU: {result["total"]:.2f} % of one core')
    for line in thread_cpu.table(result['rows'], result['pid']):
        print(line)
    rate = wire['rate']
    if rate:
        print(f'bus thread: {bus.wakeups_per_s / rate:.2f} wake-ups and '
              f'{10 * bus.cpu_pct / rate * 1000:.0f} us of CPU a transaction')
    counters = result['counters']
    print(f'wire: {rate:.1f} transactions/s of a wire limit of {wire["limit"]:.1f}/s '
          f'for this mix: {wire["fraction"]:.1%}; gap violations {counters.gap_violations}, '
          f'collisions {counters.collisions}')


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('window_s', nargs='?', type=float, default=10.0)
    parser.add_argument('baudrate', nargs='?', type=int, default=BAUDRATE)
    parser.add_argument('--listen', nargs='?', type=listened_topics, const=['all'],
                        default=[], metavar='TOPIC,...',
                        help='subscribe during the window (a child process) to every topic '
                        'of every device and /diagnostics, or to the device topics named '
                        '(e.g. status_word); give the positional arguments before it')
    parser.add_argument('--calls', type=float, default=0.0,
                        help='Trigger calls a second during the window (a child process)')
    parser.add_argument('--runs', type=int, default=1, help='measurements, each afresh')
    parser.add_argument('--compare', action='append', default=[], metavar='LABEL=DIR',
                        help='run the drive_bridge package in DIR (LABEL= alone: the '
                        'installed one), the versions in turn; repeatable')
    parser.add_argument('--listener-child', nargs='*', help=argparse.SUPPRESS)
    parser.add_argument('--caller-child', nargs='*', help=argparse.SUPPRESS)
    arguments = parser.parse_args()
    if arguments.listener_child is not None:
        listen(arguments.listener_child)
        return
    if arguments.caller_child is not None:
        call_triggers(float(arguments.caller_child[0]), arguments.caller_child[1:])
        return
    print(thread_cpu.machine())
    window_s, baudrate = arguments.window_s, arguments.baudrate
    print(f'drive_bridge_node, 4 MCD 500 + 4 FC 51 at 100 Hz, {baudrate} baud 8E1 timing '
          f'through the wire pacer, ' +
          listening(arguments.listen) +
          (f', {arguments.calls:g} Trigger calls/s' if arguments.calls else '') +
          f'; {conditions()}')
    rclpy.init()
    compared = versions(arguments.compare)
    results: Dict[str, List[Dict]] = {label: [] for label, _ in compared}
    try:
        for index in range(arguments.runs):
            for label, source in compared:
                results[label].append(measure(window_s, baudrate, arguments.listen,
                                              arguments.calls, source))
                print_run(results[label][-1], index, label)
    finally:
        rclpy.try_shutdown()
    for label, runs in results.items():
        print_summary(label, runs)
    print(thread_cpu.load())


def listened_topics(text: str) -> List[str]:
    """Return ``--listen``'s topics (``['all']``: every one); raise on a name that is none."""
    topics = text.split(',')
    if topics == ['all']:
        return topics
    unknown = sorted(set(topics) - set(DEVICE_TOPICS))
    if unknown:
        raise argparse.ArgumentTypeError(
            f'no such device topic: {", ".join(unknown)} (the topics: '
            f'{", ".join(DEVICE_TOPICS)}; or all, alone)')
    return topics


def listening(listen: List[str]) -> str:
    """Return what the listener subscribes to, in words."""
    if not listen:
        return 'no subscriber'
    if listen == ['all']:
        return 'every topic subscribed'
    return f'{",".join(listen)} of every device subscribed'


def print_summary(label: str, runs: List[Dict]) -> None:
    """Print the median and range of each figure over the runs of one version."""
    def spread(values: List[float]) -> str:
        values = sorted(values)
        return f'{statistics.median(values):.2f} [{values[0]:.2f}, {values[-1]:.2f}]'
    threads = [thread_cpu.by_name(run['rows']) for run in runs]
    for shares in threads:
        shares['Fast DDS'] = sum(value for name, value in shares.items()
                                 if name.startswith('dds'))
    names = ('drive-bridge-bus', 'ros-executor', 'ros-commands', 'Fast DDS')
    print(f'{label or "node"}: CPU {spread([run["total"] for run in runs])} % of one core; ' +
          ', '.join(f'{name} {spread([shares.get(name, 0.0) for shares in threads])}'
                    for name in names) +
          f'; wire {spread([100 * run["wire"]["fraction"] for run in runs])} %; bus thread '
          f'{spread([run["bus"].wakeups_per_s / run["wire"]["rate"] for run in runs])} '
          'wake-ups a transaction')


if __name__ == '__main__':
    main()
