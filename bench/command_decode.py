"""
Benchmark: reading a ``~/joint_commands`` message, rclpy's deserializer against joints/wire.py.

A JointState of 8 joints as ``JointStateTopicSystem`` sends it (a stamp, 8 names, 8
velocities; position and effort empty; also with 8 positions and efforts), serialized by
rclpy. Timed in this process, one thread, ``time.thread_time`` over many messages:

- ``rclpy``: ``rclpy.serialization.deserialize_message`` (what a subscription without
  ``raw=True`` does per message: the C deserializer, then the message's Python class built
  through its constructor and property setters, with ``ROS_PYTHON_CHECK_FIELDS`` as set),
  then the names and velocities taken as tuples;
- ``wire.py``: :func:`drive_bridge.ros.node.joints.wire.read_joint_command` on the same bytes.

Prints microseconds of CPU a message (median of 5 rounds) and what 100 messages a second
cost in % of one core. The machine and its load are printed first and last.
Run: .venv/bin/python bench/command_decode.py [messages per round]
"""

import statistics
import sys
import time
from typing import Callable, Dict

from paced_line import conditions, ros_environment
import thread_cpu

ros_environment()
from drive_bridge.ros.node.joints import wire  # noqa: E402, I100 - after the environment it reads
from rclpy.serialization import deserialize_message, serialize_message  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

JOINTS = 8
ROUNDS = 5
RATE_HZ = 100.0


def message(with_positions: bool) -> bytes:
    """Return a serialized 8-joint command, with or without positions and efforts."""
    command = JointState()
    command.header.stamp.sec = 1_795_770_000
    command.header.stamp.nanosec = 123_456_789
    command.name = [f'wheel{index}_joint' for index in range(1, JOINTS + 1)]
    command.velocity = [0.1 * index for index in range(JOINTS)]
    if with_positions:
        command.position = [1.5 * index for index in range(JOINTS)]
        command.effort = [0.0] * JOINTS
    return serialize_message(command)


def by_rclpy(data: bytes) -> wire.JointCommand:
    """Deserialize as rclpy does for a subscription, then take names and velocities."""
    command = deserialize_message(data, JointState)
    return wire.JointCommand(tuple(command.name), tuple(command.velocity))


def cpu_us(read: Callable[[bytes], wire.JointCommand], data: bytes, count: int) -> float:
    """Return the median CPU microseconds a message of ``read`` over ROUNDS rounds."""
    rounds = []
    for _ in range(ROUNDS):
        started = time.thread_time()
        for _ in range(count):
            read(data)
        rounds.append((time.thread_time() - started) / count * 1e6)
    return statistics.median(rounds)


def main() -> None:
    count = int(sys.argv[1]) if len(sys.argv) > 1 else 20000
    print(thread_cpu.machine())
    print(f'one 8-joint JointState command, {count} messages a round, median of {ROUNDS} '
          f'rounds, CPU time of this thread; {conditions()}')
    print('| message | bytes | rclpy us/message | wire.py us/message | rclpy / wire.py | '
          f'% of a core at {RATE_HZ:g} Hz, rclpy / wire.py |')
    print('| --- | --- | --- | --- | --- | --- |')
    for label, with_positions in (('names, velocities', False),
                                  ('names, positions, velocities, efforts', True)):
        data = message(with_positions)
        assert by_rclpy(data) == wire.read_joint_command(data)
        figures: Dict[str, float] = {
            'rclpy': cpu_us(by_rclpy, data, count),
            'wire': cpu_us(wire.read_joint_command, data, count)}
        print(f'| {label} | {len(data)} | {figures["rclpy"]:.1f} | {figures["wire"]:.1f} | '
              f'{figures["rclpy"] / figures["wire"]:.1f}x | '
              f'{figures["rclpy"] * RATE_HZ / 1e4:.2f} / {figures["wire"] * RATE_HZ / 1e4:.2f} |')
    print(thread_cpu.load())


if __name__ == '__main__':
    main()
