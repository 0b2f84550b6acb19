"""
The commands thread against stops, deactivate, SIGTERM, monitor-only and the deadman.

``~/joint_commands`` and ``<name>/speed_reference`` are taken on a thread of their own (the
commands node, :mod:`drive_bridge.ros.node.command_inputs`), so a command can arrive while a stop,
a deactivation or the exit signal's stops run on another thread. Here a stream of commands
(several hundred a second, from a thread of the test process) runs through each of those;
the motor is read from the simulated FC 51, never from the bridge: what it received (control
words, write frames) and what its model does.
"""

from contextlib import contextmanager
import math
import os
import random
import signal
import threading
from typing import Callable, Iterator

import pytest
import rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy
from safety_helpers import wait_for, write_frames
from safety_ros import (
    clean_exit, diagnostics_seen, Lifecycle, make_rig, READY_S, Session, status_values)
from sensor_msgs.msg import JointState
from std_msgs.msg import Float32

ROUNDS = 4
SCALE = 20.0  # rad/s at 100 %
STREAM_PERIOD_S = 0.002  # about 500 messages a second (less on a loaded machine)
QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)


class CommandStream:
    """Publish the latest ``value`` as fast as ``STREAM_PERIOD_S`` allows, from a thread."""

    def __init__(self, topic: str, kind, make: Callable[[float], object], value: float):
        self.node = rclpy.create_node(f'test_stream_{os.getpid()}_{id(self)}')
        self.publisher = self.node.create_publisher(kind, topic, QOS)
        self.make = make
        self.value = value
        self.sent = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def start(self) -> 'CommandStream':
        assert wait_for(lambda: self.publisher.get_subscription_count() > 0, READY_S), \
            f'nothing subscribes {self.publisher.topic_name}'
        self._thread.start()
        return self

    def _run(self) -> None:
        while not self._stop.is_set():
            self.publisher.publish(self.make(self.value))
            self.sent += 1
            self._stop.wait(STREAM_PERIOD_S)

    def close(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(5.0)
        self.node.destroy_node()


def joint_command(velocity: float) -> JointState:
    return JointState(name=['motor'], velocity=[float(velocity)])


def reference(percent: float) -> Float32:
    return Float32(data=float(percent))


@contextmanager
def streams(joint: float = None, percent: float = None) -> Iterator[list]:
    """Stream joint commands and/or speed references to the device ``motor``."""
    running = []
    try:
        if joint is not None:
            running.append(CommandStream('/drive_bridge/joint_commands', JointState,
                                         joint_command, joint).start())
        if percent is not None:
            running.append(CommandStream('/motor/speed_reference', Float32, reference,
                                         percent).start())
        yield running
    finally:
        for stream in running:
            stream.close()


def pause(session: Session, seconds: float) -> None:
    session.client.spin_until(lambda: False, seconds)


def sent_during(session: Session, stream: CommandStream, seconds: float) -> int:
    """Pause ``seconds``; return how many commands ``stream`` sent meanwhile."""
    before = stream.sent
    pause(session, seconds)
    return stream.sent - before


@pytest.mark.parametrize('round_', range(ROUNDS))
def test_deactivate_during_a_stream_of_auto_start_commands_stops_the_motor(round_, tmp_path):
    """Deactivate while nonzero commands stream: stopped, and not restarted by them."""
    rig = make_rig('fc', velocity_scale=SCALE, command_mode='auto_start')
    chance = random.Random(round_)
    with Session(rig, tmp_path / 'deactivate.yaml') as session:
        client = session.client
        assert client.wait_state('motor', 'ready', READY_S)
        with streams(joint=5.0) as running:
            assert wait_for(rig.probe.moving, 15.0), 'the nonzero command did not start it'
            pause(session, chance.uniform(0.0, 0.3))
            lifecycle = Lifecycle(client)
            assert lifecycle.transition('deactivate')
            assert wait_for(rig.probe.stopped, 10.0), 'deactivate left the motor running'
            runs = rig.probe.run_writes()
            inactive = sent_during(session, running[0], 1.0)
            # the stream went on: refused, nothing started the motor
            assert rig.probe.run_writes() == runs and rig.probe.stopped()
            assert lifecycle.transition('activate')
            # Still nonzero: a stop the node did not make itself (deactivate) keeps
            # automatic starts off until the command goes to zero and back.
            active = sent_during(session, running[0], 1.0)
            assert rig.probe.run_writes() == runs and rig.probe.stopped()
            assert rig.probe.start_edges() == 1
            running[0].value = 0.0
            pause(session, 0.3)
            running[0].value = 5.0  # zero and back: armed again, it starts
            assert wait_for(rig.probe.moving, 15.0)
            assert rig.probe.start_edges() == 2
    # The stream went on in both seconds that matter (about 500 a second on a free machine,
    # 185 with eight test workers on two cores; a total over the test of more than 500 was
    # once missed by one there).
    assert inactive > 50 and active > 50, (inactive, active)


@pytest.mark.parametrize('round_', range(ROUNDS))
def test_sigterm_during_a_stream_of_commands_stops_the_motor_and_exits_clean(
        round_, tmp_path):
    """SIGTERM while joint commands and references stream: stopped, exit 0, no error."""
    mode = ('auto_start', 'reference')[round_ % 2]
    rig = make_rig('fc', velocity_scale=SCALE, command_mode=mode)
    chance = random.Random(100 + round_)
    with Session(rig, tmp_path / 'sigterm.yaml') as session:
        client = session.client
        assert client.wait_state('motor', 'ready', READY_S)
        with streams(joint=5.0, percent=30.0) as running:
            if mode == 'reference':
                assert client.call('motor', 'start').success
            assert wait_for(rig.probe.moving, 15.0)
            pause(session, chance.uniform(0.0, 0.3))
            code, output = session.signal(signal.SIGTERM)  # the streams go on meanwhile
            assert all(stream.sent > 0 for stream in running)
    assert clean_exit(code, output), output
    assert 'ros-commands' not in output and 'internal error' not in output, output
    assert wait_for(rig.probe.stopped, 5.0), 'SIGTERM left the motor running'
    assert rig.probe.start_edges() == 1


def test_a_monitor_only_drive_gets_nothing_from_streams_of_commands(tmp_path):
    """allow_control false: hundreds of references and joint commands write nothing."""
    rig = make_rig('fc', velocity_scale=SCALE, allow_control=False, speed_reference=0.0)
    with Session(rig, tmp_path / 'monitor.yaml') as session:
        client = session.client
        assert client.wait_state('motor', 'ready', READY_S)
        with streams(joint=5.0, percent=30.0) as running:
            pause(session, 1.5)
            sent = sum(stream.sent for stream in running)
        status = diagnostics_seen(client, 'motor', lambda found: int(
            status_values(found).get('rejected_references', '0')) >= 100)
        assert status is not None, 'the references were not refused and counted'
    assert sent > 300, sent
    assert write_frames(rig.server, 1) == [], 'a monitor-only drive got a write'
    assert not rig.probe.moving()


@pytest.mark.parametrize('kind', ['joint', 'reference'])
def test_refused_commands_do_not_feed_the_deadman(kind, tmp_path):
    """A stream of refused (NaN) commands does not keep a running drive alive."""
    rig = make_rig('fc', velocity_scale=SCALE, reference_timeout=0.5)
    with Session(rig, tmp_path / 'deadman.yaml') as session:
        client = session.client
        assert client.wait_state('motor', 'ready', READY_S)
        values = {'joint': {'joint': math.nan}, 'reference': {'percent': math.nan}}[kind]
        with streams(**values) as running:
            assert client.call('motor', 'start').success
            assert wait_for(rig.probe.moving, 15.0)
            # Only the start fed the deadman: it stops the drive 0.5 s later.
            assert wait_for(rig.probe.stopped, 10.0), 'refused commands fed the deadman'
            assert running[0].sent > 100
        status = diagnostics_seen(client, 'motor', lambda found: int(
            status_values(found).get('deadman_stops', '0')) >= 1)
        assert status is not None
        assert int(status_values(status)['rejected_references']) > 100
