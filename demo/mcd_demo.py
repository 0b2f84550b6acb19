"""
Demo: a simulated MCD 500 on a pty, the node attached to it, start -> running -> stop.

Run through ``scripts/demo.sh``, which sets up the venv and the environment.
"""

import os
import signal
import subprocess
import sys
import time

import rclpy
from rclpy.qos import DurabilityPolicy, QoSProfile
from std_msgs.msg import Float32, String
from std_srvs.srv import Trigger

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
LINK = '/tmp/drive_bridge_demo_tty'


class Watcher:
    """Print state, current and temperature as they change."""

    def __init__(self, node):
        self.state = ''
        self.started = time.monotonic()
        self.current = 0.0
        self.temperature = 0.0
        self.last_print = 0.0
        latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        node.create_subscription(String, 'starter/state', self.on_state, latched)
        node.create_subscription(Float32, 'starter/motor_current', self.on_current, 10)
        node.create_subscription(Float32, 'starter/motor_temperature', self.on_temp, 10)

    def line(self, text):
        print(f'{time.monotonic() - self.started:6.2f} s  {text}', flush=True)

    def on_state(self, message):
        if message.data != self.state:
            self.state = message.data
            self.line(f'state: {message.data}')

    def on_current(self, message):
        self.current = message.data
        now = time.monotonic()
        if now - self.last_print >= 0.4:
            self.last_print = now
            self.line(f'    motor current {self.current:6.1f} A   '
                      f'motor temperature {self.temperature:3.0f} %   ({self.state})')

    def on_temp(self, message):
        self.temperature = message.data


def spin_until(node, predicate, timeout_s):
    deadline = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > deadline:
            raise SystemExit('demo: timed out waiting')
        rclpy.spin_once(node, timeout_sec=0.05)


def call(node, client, watcher, name):
    watcher.line(f'calling {name} ...')
    future = client.call_async(Trigger.Request())
    rclpy.spin_until_future_complete(node, future, timeout_sec=10)
    result = future.result()
    watcher.line(f'{name}: success={result.success} "{result.message}"')
    if not result.success:
        raise SystemExit(1)


def main():
    sim = subprocess.Popen([sys.executable, '-m', 'drive_bridge.sim.cli', '--device',
                            'mcd500:20', '--link', LINK, '--start-time', '3',
                            '--stop-time', '2'], stdout=subprocess.PIPE, text=True)
    assert sim.stdout.readline().startswith('pty:')
    bridge = subprocess.Popen([sys.executable, '-m', 'drive_bridge.ros.node.entry', '--ros-args',
                               '--params-file', os.path.join(ROOT, 'config', 'demo_mcd500.yaml')])
    rclpy.init()
    node = rclpy.create_node('drive_bridge_demo')
    try:
        watcher = Watcher(node)
        start = node.create_client(Trigger, 'starter/start')
        stop = node.create_client(Trigger, 'starter/stop')
        assert start.wait_for_service(timeout_sec=20) and stop.wait_for_service(timeout_sec=5)
        spin_until(node, lambda: watcher.state == 'ready', 20)
        call(node, start, watcher, 'starter/start')
        spin_until(node, lambda: watcher.state == 'running', 10)
        end = time.monotonic() + 4
        spin_until(node, lambda: time.monotonic() > end, 10)
        call(node, stop, watcher, 'starter/stop')
        spin_until(node, lambda: watcher.state == 'ready', 10)
        watcher.line('demo finished: ready -> starting -> running -> stopping -> ready')
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
        for process in (bridge, sim):
            process.send_signal(signal.SIGTERM)
            process.wait(timeout=10)


if __name__ == '__main__':
    main()
