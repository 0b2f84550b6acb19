"""
The commands thread (:mod:`drive_bridge.ros.node.commands_thread`): what its ``stop`` promises.

The node ends the thread before it closes the bus; a True return must mean that no command
callback runs or will run, and a callback that is still running must be waited for again by
the next ``stop`` (the node calls it at the bus's close and again at the node's
destruction), never reported as ended.
"""

import os
import threading
import time

import pytest
import rclpy
from std_msgs.msg import Float32

commands_thread = pytest.importorskip('drive_bridge.ros.node.commands_thread')

TOPIC = f'/test_commands_thread_{os.getpid()}'


class Rig:
    """A node on a CommandsThread whose callback blocks until released; a publisher node."""

    def __init__(self):
        self.node = rclpy.create_node(f'commands_thread_{os.getpid()}',
                                      start_parameter_services=False, enable_rosout=False)
        self.entered = threading.Event()
        self.release = threading.Event()
        self.taken = []
        self.node.create_subscription(Float32, TOPIC, self._callback, 10)
        self.thread = commands_thread.CommandsThread(self.node)
        self.sender = rclpy.create_node(f'commands_sender_{os.getpid()}')
        self.publisher = self.sender.create_publisher(Float32, TOPIC, 10)
        self.seen = []  # what a witness on the sender's node received: the message went out
        self.sender.create_subscription(Float32, TOPIC, lambda m: self.seen.append(m.data), 10)

    def _callback(self, message: Float32) -> None:
        self.taken.append(message.data)
        self.entered.set()
        self.release.wait(10.0)

    def send(self, value: float) -> None:
        """Publish ``value`` and wait until the witness has it."""
        self.publisher.publish(Float32(data=value))
        deadline = time.monotonic() + 10.0
        while value not in self.seen and time.monotonic() < deadline:
            rclpy.spin_once(self.sender, timeout_sec=0.05)
        assert value in self.seen

    def wait_matched(self) -> None:
        deadline = time.monotonic() + 10.0
        while self.publisher.get_subscription_count() < 2 and time.monotonic() < deadline:
            rclpy.spin_once(self.sender, timeout_sec=0.05)
        assert self.publisher.get_subscription_count() == 2

    def close(self) -> None:
        self.release.set()
        self.thread.stop()
        self.sender.destroy_node()
        self.node.destroy_node()


@pytest.fixture
def rig():
    made = Rig()
    yield made
    made.close()


def test_stop_waits_for_a_running_callback_and_says_so_until_it_ends(rig):
    rig.wait_matched()
    rig.send(1.0)
    assert rig.entered.wait(10.0)
    assert rig.thread.stop(timeout_s=0.2) is False  # the callback runs: not ended
    assert rig.thread.stop(timeout_s=0.2) is False  # asked again: still not, waited again
    rig.release.set()
    assert rig.thread.stop(timeout_s=10.0) is True
    assert rig.taken == [1.0]


def test_no_callback_runs_after_stop(rig):
    rig.release.set()
    rig.wait_matched()
    rig.send(1.0)
    deadline = time.monotonic() + 10.0
    while rig.taken != [1.0] and time.monotonic() < deadline:
        time.sleep(0.01)
    assert rig.taken == [1.0]
    assert rig.thread.stop() is True
    rig.send(2.0)  # delivered (the witness has it) ...
    rig.send(3.0)
    assert rig.taken == [1.0]  # ... but not taken: the thread has ended
    assert rig.thread.stop() is True  # idempotent
