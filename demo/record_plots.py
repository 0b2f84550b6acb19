"""
Record a simulated soft start and an FC 51 speed ramp through the node, and plot both.

Writes ``docs/recording.mcap`` (not committed) and the PNGs in ``docs/`` that the README
shows. Run through ``scripts/record_plots.sh``, which sets up the venv and environment.
"""

import os
import signal
import subprocess
import sys
import tempfile
import time

from diagnostic_msgs.msg import DiagnosticArray
from drive_bridge.config import write_params_file
from drive_bridge.ros.recorder import McapRecorder
from drive_bridge.tools.plot_recording import plot, read_recording
import rclpy
from rclpy.qos import DurabilityPolicy, QoSProfile
from std_msgs.msg import Float32, String
from std_srvs.srv import Trigger

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DOCS = os.path.join(ROOT, 'docs')
LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
TOPICS = {'/starter/state': String, '/starter/motor_current': Float32,
          '/conveyor/state': String, '/conveyor/motor_current': Float32,
          '/conveyor/speed_feedback': Float32, '/diagnostics': DiagnosticArray}
BUS = {'parity': 'N', 'timeout': 0.2}
DEVICES = {'starter': {'family': 'mcd', 'model': 'mcd500', 'address': 20, 'poll_rate': 10.0},
           'conveyor': {'family': 'fc', 'model': 'fc51', 'address': 1, 'poll_rate': 10.0,
                        'speed_reference': 80.0}}


class Session:
    """An rclpy node that records and calls the bridge's services."""

    def __init__(self, path: str):
        self.node = rclpy.create_node('drive_bridge_record_plots')
        self.recorder = McapRecorder(self.node, path, TOPICS,
                                     qos={'/starter/state': LATCHED,
                                          '/conveyor/state': LATCHED})
        self.state = {}
        for name in ('starter', 'conveyor'):
            self.node.create_subscription(String, f'/{name}/state',
                                          lambda m, n=name: self.state.update({n: m.data}),
                                          LATCHED)
        self.reference = self.node.create_publisher(Float32, '/conveyor/speed_reference', 10)

    def wait(self, predicate, timeout_s: float = 20.0) -> None:
        deadline = time.monotonic() + timeout_s
        while not predicate():
            if time.monotonic() > deadline:
                raise SystemExit('record_plots: timed out waiting')
            rclpy.spin_once(self.node, timeout_sec=0.05)

    def pause(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        self.wait(lambda: time.monotonic() > end)

    def call(self, name: str, command: str) -> None:
        client = self.node.create_client(Trigger, f'/{name}/{command}')
        assert client.wait_for_service(timeout_sec=20)
        future = client.call_async(Trigger.Request())
        rclpy.spin_until_future_complete(self.node, future, timeout_sec=10)
        print(f'{name}/{command}: {future.result().message}', flush=True)


def run(session: Session) -> None:
    session.wait(lambda: session.state.get('starter') == 'ready'
                 and session.state.get('conveyor') == 'ready')
    session.pause(1.0)
    session.call('starter', 'start')
    session.wait(lambda: session.state['starter'] == 'running')
    session.pause(2.0)
    session.call('starter', 'stop')
    session.wait(lambda: session.state['starter'] == 'ready')
    session.call('conveyor', 'start')
    session.pause(5.0)
    session.reference.publish(Float32(data=-40.0))  # reverse at 40 %
    session.pause(6.0)
    session.call('conveyor', 'stop')
    session.wait(lambda: session.state['conveyor'] == 'ready')
    session.pause(1.0)


def main() -> None:
    os.makedirs(DOCS, exist_ok=True)
    link = os.path.join(tempfile.mkdtemp(), 'tty_record')
    sim = subprocess.Popen([sys.executable, '-m', 'drive_bridge.sim.cli', '--device',
                            'mcd500:20', '--device', 'fc51:1', '--link', link,
                            '--start-time', '3', '--stop-time', '2', '--ramp-up', '4',
                            '--ramp-down', '4'], stdout=subprocess.PIPE, text=True,
                           stdin=subprocess.DEVNULL)
    assert sim.stdout.readline().startswith('pty:')
    params = os.path.join(os.path.dirname(link), 'params.yaml')
    write_params_file(params, dict(BUS, port=link), DEVICES)
    bridge = subprocess.Popen([sys.executable, '-m', 'drive_bridge.ros.node', '--ros-args',
                               '--params-file', params])
    path = os.path.join(DOCS, 'recording.mcap')
    rclpy.init()
    session = Session(path)
    try:
        run(session)
    finally:
        session.recorder.close()
        session.node.destroy_node()
        rclpy.try_shutdown()
        for process in (bridge, sim):
            process.send_signal(signal.SIGTERM)
            process.wait(timeout=10)
    series = read_recording(path)
    plot(series, os.path.join(DOCS, 'soft_start.png'), ['starter'],
         'MCD 500 (simulated): soft start, run, soft stop')
    plot(series, os.path.join(DOCS, 'fc51_ramp.png'), ['conveyor'],
         'FC 51 (simulated): start at 80 %, reverse to -40 %, stop')
    print(f'wrote {path}, docs/soft_start.png, docs/fc51_ramp.png', flush=True)


if __name__ == '__main__':
    main()
