"""
Benchmark: CPU of drive_bridge_node as the ros2_control side of 8 joints, 100 Hz commands.

8 FC 51s, all joints (``velocity_scale``), started and running, each polled as fast as the
line allows (``poll_rate`` 100) on one line paced by the wire pacer (8E1 timing, 11 bits a
character). A client in a child process behaves as ``JointStateTopicSystem`` in a 100 Hz
controller manager: it subscribes to ``~/joint_states`` (sensor-data QoS) and publishes one
JointState with the 8 velocity commands every 10 ms (changing a little each time, as a
controller's would) to ``~/joint_commands``. The node's CPU is read per thread from the
scheduler's accounting over a fixed window (``thread_cpu.py``), in three cases:

- ``not joints``: the same drives without velocity_scale, no client (the baseline);
- ``states only``: joints, the client subscribed, no commands;
- ``commands``: the client also sends its 100 Hz commands.

What the commands add is ``commands`` minus ``states only`` of the same round. Also
printed: the bus transactions per second (the pacer's frame log; commands must not add
any), the states received and the commands sent per second, and the CPU of the node's
threads: the bus thread, the executor (``ros-executor``: services, parameters, timers), the
commands thread (``ros-commands``: ``~/joint_commands`` and ``speed_reference``; on the
executor before issue 29) and Fast DDS's threads. Each case is run several times, the cases
in turn; the table gives the median and the range. ``--compare LABEL=DIR`` (repeatable)
runs the node from each directory's ``drive_bridge`` package in turn (``LABEL=`` alone: the
installed one), so that two versions meet the same noise.
``--floor`` also measures a bare rclpy process that takes the same commands as the node's
commands thread does (its own node, serialized, EventsExecutor) with an empty callback:
what rclpy and Fast DDS cost per message before any work of the node's.
Run: .venv/bin/python bench/joint_cpu.py [window s] [baud] [runs] [--compare LABEL=DIR ...]
[--floor]
"""

import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import time
from typing import Dict, List, Optional

from drive_bridge.sim.wire_pacer import LineTiming
from node_cpu import wait_until_ready
from paced_line import (
    conditions, node_bus, NodeProcess, PacedSimulator, ros_environment, simulator_devices,
    versions, wait_for)
import thread_cpu

ros_environment()
import rclpy  # noqa: E402, I100 - after the environment it reads
from rclpy.qos import qos_profile_sensor_data, QoSProfile, ReliabilityPolicy  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

JOINTS = 8
SCALE = 20.0
COMMAND_PERIOD_S = 0.01  # the controller manager's 100 Hz
WARM_UP_S = 2.0
THREADS = ('drive-bridge-bus', 'ros-executor', 'ros-commands')
CASES = (('not joints', False, None), ('states only', True, 'listen'),
         ('commands', True, 'commands'))


def devices(joints: bool, count: int = JOINTS) -> Dict[str, Dict]:
    """Return ``count`` FC 51 device blocks, joints or not, each at a 25 % reference."""
    blocks = {}
    for unit in range(1, count + 1):
        block = {'family': 'fc', 'model': 'fc51', 'address': unit, 'poll_rate': 100.0,
                 'speed_reference': 25.0}
        if joints:
            block['velocity_scale'] = SCALE
        blocks[f'wheel{unit}'] = block
    return blocks


def start_drives(names: List[str]) -> None:
    """Start every drive through its service (a start whose reply was lost: once more)."""
    node = rclpy.create_node(f'bench_starter_{os.getpid()}')
    try:
        for name in names:
            client = node.create_client(Trigger, f'{name}/start')
            if not client.wait_for_service(timeout_sec=10.0):
                raise RuntimeError(f'no {name}/start service')
            for attempt in range(3):
                future = client.call_async(Trigger.Request())
                rclpy.spin_until_future_complete(node, future, timeout_sec=10.0)
                if future.done() and future.result().success:
                    break
            else:
                raise RuntimeError(f'{name}/start failed: {future.result()}')
    finally:
        node.destroy_node()


def client_main(mode: str, seconds: float) -> None:
    """Be JointStateTopicSystem for ``seconds``: take states, send 100 Hz commands."""
    rclpy.init()
    node = rclpy.create_node(f'bench_joint_client_{os.getpid()}')
    counts = {'states': 0, 'commands': 0}
    node.create_subscription(JointState, '/drive_bridge/joint_states',
                             lambda message: counts.__setitem__('states', counts['states'] + 1),
                             qos_profile_sensor_data)
    publisher = node.create_publisher(JointState, '/drive_bridge/joint_commands',
                                      QoSProfile(depth=1,
                                                 reliability=ReliabilityPolicy.RELIABLE))
    names = [f'wheel{unit}' for unit in range(1, JOINTS + 1)]

    def write() -> None:
        phase = counts['commands'] * COMMAND_PERIOD_S
        message = JointState(name=names, velocity=[5.0 + 0.5 * math.sin(phase + index)
                                                   for index in range(JOINTS)])
        message.header.stamp = node.get_clock().now().to_msg()
        publisher.publish(message)
        counts['commands'] += 1

    if mode == 'commands':
        node.create_timer(COMMAND_PERIOD_S, write)
    print('client ready', flush=True)
    started = time.monotonic()
    while time.monotonic() - started < seconds:
        rclpy.spin_once(node, timeout_sec=0.05)
    elapsed = time.monotonic() - started
    print(json.dumps({key: value / elapsed for key, value in counts.items()}), flush=True)
    node.destroy_node()
    rclpy.try_shutdown()


def receiver_main() -> None:
    """
    Take ``~/joint_commands`` as the node's commands thread does, with an empty callback.

    A node of its own (no parameter services, no /rosout), the subscription serialized,
    spun by rclpy's EventsExecutor: what rclpy and Fast DDS cost per message on this
    machine before any of the node's own work (the floor of the commands' cost).
    """
    from rclpy.executors import ExternalShutdownException
    from rclpy.experimental import EventsExecutor
    from rclpy.parameter import Parameter
    rclpy.init()
    node = rclpy.create_node('drive_bridge', enable_rosout=False,
                             start_parameter_services=False,
                             parameter_overrides=[Parameter('start_type_description_service',
                                                            value=False)])
    node.create_subscription(JointState, '/drive_bridge/joint_commands', lambda data: None,
                             QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE),
                             raw=True)
    executor = EventsExecutor()
    executor.add_node(node)
    print('receiver ready', flush=True)
    try:
        while rclpy.ok():
            executor.spin_once(timeout_sec=0.5)
    except (ExternalShutdownException, KeyboardInterrupt):
        pass  # stopped by the bench (SIGINT/SIGTERM)


def run_floor(window_s: float) -> Dict:
    """Measure the floor: a bare receiver process of the client's 100 Hz commands."""
    receiver = subprocess.Popen([sys.executable, __file__, '--receiver'],
                                stdout=subprocess.PIPE, text=True)
    helper = None
    try:
        assert receiver.stdout.readline().strip() == 'receiver ready'
        helper = subprocess.Popen(
            [sys.executable, __file__, '--client', 'commands', str(WARM_UP_S + window_s + 5.0)],
            stdout=subprocess.PIPE, text=True)
        assert helper.stdout.readline().strip() == 'client ready'
        wait_for(lambda: False, WARM_UP_S)
        before = thread_cpu.sample(receiver.pid)
        started_s = time.monotonic()
        time.sleep(window_s)
        after = thread_cpu.sample(receiver.pid)
        ended_s = time.monotonic()
        rates = json.loads(helper.stdout.readline())
    finally:
        for child in (helper, receiver):
            if child is not None:
                child.terminate()
                child.wait()
                child.stdout.close()
    rows = thread_cpu.shares(before, after, ended_s - started_s, {})
    shares = thread_cpu.by_name(rows)
    return {'cpu': thread_cpu.total_pct(rows), 'commands': rates['commands'],
            'dds': sum(value for name, value in shares.items() if name.startswith('dds')),
            'python': sum(value for name, value in shares.items()
                          if not name.startswith('dds'))}


def run_case(baudrate: int, window_s: float, joints: bool, client: Optional[str],
             source: str) -> Dict:
    """Measure one case; return its figures."""
    blocks = devices(joints)
    line = PacedSimulator(simulator_devices(blocks), LineTiming(baudrate, 'E', 1))
    node = NodeProcess(node_bus(line.path, baudrate), blocks, source=source)
    helper = None
    try:
        wait_until_ready(list(blocks))
        start_drives(list(blocks))
        if client is not None:
            helper = subprocess.Popen(
                [sys.executable, __file__, '--client', client,
                 str(WARM_UP_S + window_s + 5.0)], stdout=subprocess.PIPE, text=True,
                env=dict(os.environ))
            assert helper.stdout.readline().strip() == 'client ready'
        wait_for(lambda: False, WARM_UP_S)
        names = thread_cpu.python_thread_names(node.pid)
        window = thread_cpu.measure_window(node.pid, window_s)
        wire = line.wire_figures(window.started_s, window.ended_s)
        rates = {}
        if helper is not None:
            rates = json.loads(helper.stdout.readline())
    finally:
        if helper is not None:
            helper.terminate()
            helper.wait()
            helper.stdout.close()
        node.stop()
        line.close()
    rows = window.shares(names)
    shares = thread_cpu.by_name(rows)
    figures = {'cpu': thread_cpu.total_pct(rows), 'wire': wire['rate'],
               'states': rates.get('states', 0.0), 'commands': rates.get('commands', 0.0),
               'dds': sum(value for name, value in shares.items() if name.startswith('dds'))}
    figures.update({name: shares.get(name, 0.0) for name in THREADS})
    return figures


def cell(values: List[float]) -> str:
    """Return the median [lowest, highest] of ``values``."""
    values = sorted(values)
    if len(values) == 1:
        return f'{values[0]:.1f}'
    return f'{statistics.median(values):.1f} [{values[0]:.1f}, {values[-1]:.1f}]'


def print_table(results: Dict[str, Dict[str, List[Dict]]]) -> None:
    """Print one row per version and case, and what the commands added."""
    print('| version | case | node CPU, % of one core | bus thread | executor | commands '
          'thread | Fast DDS | bus tx/s | joint_states/s received | commands/s sent |')
    print('| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |')
    for label, cases in results.items():
        for case, rows in cases.items():
            cells = [cell([row[key] for row in rows]) for key in
                     ('cpu', *THREADS, 'dds', 'wire', 'states', 'commands')]
            print(f'| {label or "this"} | {case} | ' + ' | '.join(cells) + ' |')
    for label, cases in results.items():
        added = [with_commands['cpu'] - states['cpu'] for with_commands, states in
                 zip(cases['commands'], cases['states only'])]
        print(f'{label or "this"}: 100 Hz commands add {cell(added)} % of one core '
              '(commands - states only, same round)')


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('window_s', nargs='?', type=float, default=10.0)
    parser.add_argument('baudrate', nargs='?', type=int, default=38400)
    parser.add_argument('runs', nargs='?', type=int, default=3)
    parser.add_argument('--compare', action='append', default=[], metavar='LABEL=DIR')
    parser.add_argument('--floor', action='store_true',
                        help='also measure a bare receiver of the commands (the floor)')
    parser.add_argument('--client', nargs=2, help=argparse.SUPPRESS)
    parser.add_argument('--receiver', action='store_true', help=argparse.SUPPRESS)
    arguments = parser.parse_args()
    if arguments.client:
        client_main(arguments.client[0], float(arguments.client[1]))
        return
    if arguments.receiver:
        receiver_main()
        return
    print(thread_cpu.machine())
    print(f'drive_bridge_node, {JOINTS} FC 51 running, poll_rate 100 (as fast as the line '
          f'allows), {arguments.baudrate} baud 8E1 timing through the wire pacer, '
          f'{arguments.window_s:g} s windows, {arguments.runs} runs a case: median [lowest, '
          f'highest]; {conditions()}')
    rclpy.init()
    compared = versions(arguments.compare)
    results = {label: {case: [] for case, *_ in CASES} for label, _ in compared}
    floors: List[Dict] = []
    try:
        for _ in range(arguments.runs):  # in turn, so that a noisy minute hits them all
            for label, source in compared:
                for case, joints, client in CASES:
                    results[label][case].append(run_case(
                        arguments.baudrate, arguments.window_s, joints, client, source))
            if arguments.floor:
                floors.append(run_floor(arguments.window_s))
    finally:
        rclpy.try_shutdown()
    print_table(results)
    if floors:
        print(f'floor: a bare rclpy process taking the same commands (EventsExecutor, '
              f'serialized, empty callback): {cell([f["cpu"] for f in floors])} % of one core '
              f'(Python thread {cell([f["python"] for f in floors])}, Fast DDS '
              f'{cell([f["dds"] for f in floors])}) at '
              f'{cell([f["commands"] for f in floors])} commands/s')
    print(thread_cpu.load())


if __name__ == '__main__':
    main()
