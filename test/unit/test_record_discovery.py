"""drive_bridge_record --all: when the bridge's topics count as all discovered (a fake clock)."""

import pytest

cli = pytest.importorskip('drive_bridge.ros.record.cli')  # rclpy: not in the pymodbus 3.6.9 venv

STATE = {'/line1/feeder/state': 'std_msgs/msg/String'}
REFERENCE = {'/line1/feeder/speed_reference': 'std_msgs/msg/Float32'}


def test_topics_settle_half_a_second_after_the_last_one_with_the_commands_node():
    settled = cli._Settled()
    assert not settled.after(STATE, True, 10.0)
    assert not settled.after(STATE, True, 10.4)
    assert not settled.after({**STATE, **REFERENCE}, True, 10.45)  # one more came in
    assert not settled.after({**STATE, **REFERENCE}, True, 10.9)
    assert settled.after({**STATE, **REFERENCE}, True, 10.95)


def test_without_the_commands_node_the_topics_settle_after_two_seconds():
    settled = cli._Settled()
    assert not settled.after(STATE, False, 0.0)
    assert not settled.after(STATE, False, 1.9)
    assert settled.after(STATE, False, 2.0)


def test_topics_that_went_and_came_back_count_from_their_return():
    settled = cli._Settled()
    assert not settled.after(STATE, True, 0.0)
    assert not settled.after({}, True, 0.3)
    assert not settled.after(STATE, True, 0.6)
    assert settled.after(STATE, True, 1.1)
