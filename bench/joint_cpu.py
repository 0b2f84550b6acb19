"""
Benchmark: CPU of drive_bridge_node as the ros2_control side of 8 joints, 100 Hz commands.

8 FC 51s, all joints (``velocity_scale``), started and running, each polled as fast as the
line allows (``poll_rate`` 100) on one line paced by the wire pacer (8E1 timing, 11 bits a
character). A client in a child process behaves as ``JointStateTopicSystem`` in a 100 Hz
controller manager: it subscribes to ``~/joint_states`` (sensor-data QoS) and publishes one
JointState with the 8 velocity commands every 10 ms (changing a little each time, as a
controller's would) to ``~/joint_commands``. The node's CPU is read from ``/proc`` over a
fixed window (see ``node_cpu.py``), in four cases:

- ``not joints``: the same drives without velocity_scale, no client (the baseline);
- ``states only``: joints, the client subscribed, no commands;
- ``commands, per joint``: 100 Hz commands, one JointState per reading (the node's way);
- ``commands, batched``: 100 Hz commands, one JointState per round of the 8 joints
  (``drive_bridge.ros.joints.interface.BATCH_STATES``, set by this bench in the node
  process).

Also printed: the bus transactions per second (the pacer's frame log): 100 Hz commands
must not add any. Each case is run several times, in turn; the table gives the median and
the range. Run: .venv/bin/python bench/joint_cpu.py [window s] [baud] [runs]
"""

import json
import math
import os
import statistics
import subprocess
import sys
import time
from typing import Dict, List, Optional

from drive_bridge.sim.wire_pacer import LineTiming
from node_cpu import cpu_ticks, TICKS_PER_S, wait_until_ready
from paced_line import (
    node_bus, NodeProcess, PacedSimulator, ros_environment, simulator_devices, wait_for)

ros_environment()
import rclpy  # noqa: E402 - after the environment it reads
from rclpy.qos import qos_profile_sensor_data, QoSProfile, ReliabilityPolicy  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

JOINTS = 8
SCALE = 20.0
WARM_UP_S = 2.0
NODE_MAIN = ('import sys, drive_bridge.ros.joints.interface as joints; '
             'joints.BATCH_STATES = {batch}; '
             'from drive_bridge.ros.process import main; sys.exit(main())')


def devices(joints: bool) -> Dict[str, Dict]:
    """Return 8 FC 51 device blocks, joints or not, each started at 25 % by its reference."""
    blocks = {}
    for unit in range(1, JOINTS + 1):
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
        phase = counts['commands'] * 0.01
        message = JointState(name=names, velocity=[5.0 + 0.5 * math.sin(phase + index)
                                                   for index in range(JOINTS)])
        message.header.stamp = node.get_clock().now().to_msg()
        publisher.publish(message)
        counts['commands'] += 1

    if mode == 'commands':
        node.create_timer(0.01, write)
    print('client ready', flush=True)
    started = time.monotonic()
    while time.monotonic() - started < seconds:
        rclpy.spin_once(node, timeout_sec=0.05)
    elapsed = time.monotonic() - started
    print(json.dumps({key: value / elapsed for key, value in counts.items()}), flush=True)
    node.destroy_node()
    rclpy.try_shutdown()


def run_case(label: str, baudrate: int, window_s: float, joints: bool, client: Optional[str],
             batch: bool = False) -> Dict:
    """Measure one case; return its figures."""
    blocks = devices(joints)
    line = PacedSimulator(simulator_devices(blocks), LineTiming(baudrate, 'E', 1))
    node = NodeProcess(node_bus(line.path, baudrate), blocks,
                       main=('-c', NODE_MAIN.format(batch=batch)))
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
        started_s = time.monotonic()
        before = cpu_ticks(f'/proc/{node.process.pid}/stat')
        time.sleep(window_s)
        after = cpu_ticks(f'/proc/{node.process.pid}/stat')
        ended_s = time.monotonic()
        wire = line.wire_figures(started_s, ended_s)
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
    seconds = ended_s - started_s
    return {'label': label, 'cpu': 100.0 * (after - before) / TICKS_PER_S / seconds,

            'wire': wire['rate'], 'states': rates.get('states', 0.0),
            'commands': rates.get('commands', 0.0)}


CASES = (('not joints', False, None, False), ('states only', True, 'listen', False),
         ('commands, per joint', True, 'commands', False),
         ('commands, batched', True, 'commands', True))


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == '--client':
        client_main(sys.argv[2], float(sys.argv[3]))
        return
    window_s = float(sys.argv[1]) if len(sys.argv) > 1 else 10.0
    baudrate = int(sys.argv[2]) if len(sys.argv) > 2 else 38400
    repeats = int(sys.argv[3]) if len(sys.argv) > 3 else 3
    rclpy.init()
    results: Dict[str, List[Dict]] = {label: [] for label, *_ in CASES}
    try:
        for _ in range(repeats):  # the cases in turn, so that a noisy minute hits them all
            for label, joints, client, batch in CASES:
                results[label].append(run_case(label, baudrate, window_s, joints, client,
                                               batch))
    finally:
        rclpy.try_shutdown()
    print(f'drive_bridge_node, {JOINTS} FC 51 running, poll_rate 100 (as fast as the line '
          f'allows), {baudrate} baud 8E1 timing through the wire pacer, {window_s:.0f} s '
          f'windows, {repeats} runs a case: median [lowest, highest]')
    print('| case | node CPU, % of one core | bus tx/s | joint_states msgs/s received | '
          'commands/s sent |')
    print('| --- | --- | --- | --- | --- |')
    for label, rows in results.items():
        cells = []
        for key in ('cpu', 'wire', 'states', 'commands'):
            values = sorted(row[key] for row in rows)
            cells.append(f'{statistics.median(values):.1f} [{values[0]:.1f}, '
                         f'{values[-1]:.1f}]' if len(values) > 1 else f'{values[0]:.1f}')
        print(f'| {label} | ' + ' | '.join(cells) + ' |')


if __name__ == '__main__':
    main()
