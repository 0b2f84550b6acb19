"""
Record a simulated soft start and an FC 51 speed ramp through the node, and plot both.

Runs the simulators (an MCD 500 and an FC 51 on one pty), the node in the namespace /line1
with the devices of config/mixed_bus.yaml, and ``drive_bridge_record --all``, then drives a
soft start and stop of the crusher and a ramp of the feeder to 80 %, reverse to -40 % and
stop. Writes the bag and two PNGs to ``build/record_plots/`` (or ``--output DIR``);
``--update-docs`` writes the PNGs into ``docs/``, where the manual shows them. Run through
``scripts/record_plots.sh``, which sets up the venv and the environment.
"""

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import time
from typing import List, Optional

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DOCS = os.path.join(ROOT, 'docs')
DEFAULT_OUTPUT = os.path.join(ROOT, 'build', 'record_plots')
NAMESPACE = '/line1'
PLOTS = (('soft_start.png', 'crusher', 'MCD 500 (simulated): soft start, run, soft stop'),
         ('fc51_ramp.png', 'feeder', 'FC 51 (simulated): start at 80 %, reverse to -40 %, '
                                     'stop'))
BUS = {'parity': 'N', 'timeout': 0.2}
DEVICES = {'crusher': {'family': 'mcd', 'model': 'mcd500', 'address': 20, 'poll_rate': 10.0},
           'feeder': {'family': 'fc', 'model': 'fc51', 'address': 1, 'poll_rate': 10.0}}


def parse_args(argv: Optional[List[str]] = None) -> argparse.Namespace:
    """Return the options; the plots go to docs/ only with --update-docs."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--output', default=DEFAULT_OUTPUT,
                        help='directory for the bag and the PNGs (default build/record_plots)')
    parser.add_argument('--update-docs', action='store_true',
                        help="write the PNGs into docs/ (the manual's figures)")
    args = parser.parse_args(argv)
    args.bag = os.path.join(args.output, time.strftime('run_%Y%m%d-%H%M%S'))
    args.plot_dir = DOCS if args.update_docs else args.output
    return args


class Session:
    """An rclpy node that watches the states and calls the bridge's services."""

    def __init__(self):
        import rclpy
        from rclpy.qos import DurabilityPolicy, QoSProfile
        from std_msgs.msg import Float32, String
        self.rclpy = rclpy
        self.node = rclpy.create_node('drive_bridge_record_plots')
        self.state = {}
        latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        for name in DEVICES:
            self.node.create_subscription(String, f'{NAMESPACE}/{name}/state',
                                          lambda m, n=name: self.state.update({n: m.data}),
                                          latched)
        self.reference = self.node.create_publisher(Float32, f'{NAMESPACE}/feeder/'
                                                    'speed_reference', 10)
        self.float32 = Float32

    def wait(self, predicate, timeout_s: float = 20.0) -> None:
        deadline = time.monotonic() + timeout_s
        while not predicate():
            if time.monotonic() > deadline:
                raise SystemExit('record_plots: timed out waiting')
            self.rclpy.spin_once(self.node, timeout_sec=0.05)

    def pause(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        self.wait(lambda: time.monotonic() > end)

    def call(self, name: str, command: str) -> None:
        from std_srvs.srv import Trigger
        client = self.node.create_client(Trigger, f'{NAMESPACE}/{name}/{command}')
        assert client.wait_for_service(timeout_sec=20)
        future = client.call_async(Trigger.Request())
        self.rclpy.spin_until_future_complete(self.node, future, timeout_sec=10)
        print(f'{name}/{command}: {future.result().message}', flush=True)

    def set_reference(self, percent: float) -> None:
        self.reference.publish(self.float32(data=float(percent)))

    def recorder_subscribed(self) -> bool:
        topics = [f'{NAMESPACE}/{name}/state' for name in DEVICES] + \
            [f'{NAMESPACE}/feeder/speed_reference']
        return all(any(info.node_name == 'drive_bridge_record'
                       for info in self.node.get_subscriptions_info_by_topic(topic))
                   for topic in topics)


def drive(session: Session) -> None:
    """Soft start and stop of the crusher, then the feeder's ramp, reverse and stop."""
    session.wait(lambda: session.state.get('crusher') == 'ready'
                 and session.state.get('feeder') == 'ready')
    session.wait(session.recorder_subscribed)
    session.wait(lambda: session.reference.get_subscription_count() >= 2)
    session.pause(1.0)
    session.call('crusher', 'start')
    session.wait(lambda: session.state['crusher'] == 'running')
    session.pause(2.0)
    session.call('crusher', 'stop')
    session.wait(lambda: session.state['crusher'] == 'ready')
    session.set_reference(80.0)
    session.call('feeder', 'start')
    session.pause(5.0)
    session.set_reference(-40.0)  # reverse at 40 %
    session.pause(6.0)
    session.call('feeder', 'stop')
    session.wait(lambda: session.state['feeder'] == 'ready')
    session.pause(1.0)


def start(command: List[str], **options) -> subprocess.Popen:
    """Start a child with Ctrl-C restored, so SIGINT ends it as at a terminal."""
    return subprocess.Popen(command, stdin=subprocess.DEVNULL,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
                            **options)


def record(args: argparse.Namespace) -> None:
    """Run the simulators, the node and the recorder, and drive the two devices."""
    import rclpy
    from drive_bridge.config.params_file import write_params_file
    link = os.path.join(tempfile.mkdtemp(), 'tty_record')
    sim = start([sys.executable, '-m', 'drive_bridge.sim.cli', '--device', 'mcd500:20',
                 '--device', 'fc51:1', '--link', link, '--start-time', '3', '--stop-time', '2',
                 '--ramp-up', '4', '--ramp-down', '4'], stdout=subprocess.PIPE, text=True)
    assert sim.stdout.readline().startswith('pty:')
    params = write_params_file(os.path.join(os.path.dirname(link), 'params.yaml'),
                               dict(BUS, port=link), DEVICES)
    bridge = start([sys.executable, '-m', 'drive_bridge.ros.node.entry', '--ros-args',
                    '--params-file', params, '-r', f'__ns:={NAMESPACE}'])
    recorder = start([sys.executable, '-m', 'drive_bridge.ros.record.cli', '--all', '--namespace',
                      NAMESPACE, '-o', args.bag])
    rclpy.init()
    session = Session()
    try:
        drive(session)
    finally:
        session.node.destroy_node()
        rclpy.try_shutdown()
        for process, number in ((recorder, signal.SIGINT), (bridge, signal.SIGTERM),
                                (sim, signal.SIGTERM)):
            process.send_signal(number)
            process.wait(timeout=15)
    if recorder.returncode != 0:
        raise SystemExit(f'record_plots: drive_bridge_record exited {recorder.returncode}')


def main(argv: Optional[List[str]] = None) -> None:
    args = parse_args(argv)
    os.makedirs(args.output, exist_ok=True)
    record(args)
    from drive_bridge.tools.plot_recording import plot, read_recording
    recording = read_recording(args.bag)
    for filename, device, title in PLOTS:
        path = os.path.join(args.plot_dir, filename)
        plot(recording, path, [device], title)
        print(f'wrote {path}', flush=True)
    print(f'bag: {args.bag}', flush=True)


if __name__ == '__main__':
    main()
