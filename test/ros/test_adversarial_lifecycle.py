"""
Monitor only, a site that forbids enabling control at runtime, and the lifecycle.

``allow_runtime_control_enable: false`` promises that ``allow_control`` cannot be switched
on with ``ros2 param set``. These tests set it while the node has no bus (before the first
configure, and after a cleanup), then configure and activate the node and ask the
monitor-only drive to start; what the drive received is read from the simulator.
"""

from drive_bridge.sim.devices import make_sim_server
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState
import pytest
import rclpy
from ros_helpers import RosClient, serving, start_node, stop_node, write_params

WRITE_FUNCTIONS = (0x05, 0x06, 0x0F, 0x10)
DEVICES = {'mon': {'family': 'fc', 'model': 'fc51', 'address': 2, 'poll_rate': 20.0,
                   'allow_control': False}}


def defect(reason: str):
    """Mark a test that shows a product defect: it must fail, by an assertion, for ``reason``."""
    return pytest.mark.xfail(strict=True, raises=AssertionError, reason=reason)


@pytest.fixture
def sim():
    server = make_sim_server({2: 'fc51'})
    server.record_frames = True
    with serving(server):
        yield server


@pytest.fixture
def managed(sim, tmp_path):
    params = write_params(tmp_path / 'locked.yaml',
                          {'port': sim.pty_path, 'parity': 'N', 'timeout': 0.3,
                           'autostart': False, 'allow_runtime_control_enable': False,
                           'diagnostics_period': 0.2}, DEVICES)
    process = start_node(params)
    client = RosClient(list(DEVICES), drives=['mon'])
    change = client.node.create_client(ChangeState, '/drive_bridge/change_state')
    assert change.wait_for_service(timeout_sec=15.0)

    def transition(transition_id: int) -> bool:
        future = change.call_async(ChangeState.Request(
            transition=Transition(id=transition_id)))
        rclpy.spin_until_future_complete(client.node, future, timeout_sec=10.0)
        assert future.done()
        return future.result().success

    client.transition = transition
    client.process = process
    yield client
    client.close()
    print(stop_node(process)[1])


def writes_to(sim, unit):
    with sim.lock:
        frames = list(sim.stats.frames)
    return [frame for frame in frames if frame[0] == unit and frame[1] in WRITE_FUNCTIONS]


def enable_then_start(client, sim):
    """Set mon.allow_control true (no bus now), configure, activate, start; return results."""
    result = client.set_parameter('mon.allow_control', True)
    print(f'mon.allow_control = true without a bus: {result.successful} {result.reason!r}')
    assert client.transition(Transition.TRANSITION_CONFIGURE)
    assert client.transition(Transition.TRANSITION_ACTIVATE)
    assert client.wait_state('mon', 'ready', 15.0)
    response = client.call('mon', 'start')
    print(f'mon/start: {response.success} {response.message!r}')
    client.call('mon', 'coast_stop')
    return result, response


def test_control_is_not_enabled_before_the_first_configure(managed, sim):
    """Before the first configure the device parameters are not declared: refused by rclpy."""
    result, response = enable_then_start(managed, sim)
    assert writes_to(sim, 2) == [], 'a monitor-only drive got writes'
    assert not response.success and 'monitor only' in response.message
    assert not result.successful and '\n' not in result.reason


def test_control_is_not_enabled_while_the_node_runs(managed, sim):
    """The control for the tests around it: with a bus the set is refused."""
    assert managed.transition(Transition.TRANSITION_CONFIGURE)
    assert managed.transition(Transition.TRANSITION_ACTIVATE)
    assert managed.wait_state('mon', 'ready', 15.0)
    result = managed.set_parameter('mon.allow_control', True)
    assert not result.successful and 'allow_runtime_control_enable' in result.reason
    response = managed.call('mon', 'start')
    assert not response.success and 'monitor only' in response.message
    assert writes_to(sim, 2) == []


def test_control_is_not_enabled_after_a_cleanup(managed, sim):
    assert managed.transition(Transition.TRANSITION_CONFIGURE)
    assert managed.transition(Transition.TRANSITION_ACTIVATE)
    assert managed.wait_state('mon', 'ready', 15.0)
    assert managed.transition(Transition.TRANSITION_DEACTIVATE)
    assert managed.transition(Transition.TRANSITION_CLEANUP)
    result, response = enable_then_start(managed, sim)
    assert writes_to(sim, 2) == [], 'a monitor-only drive got writes'
    assert not response.success and 'monitor only' in response.message
    assert not result.successful and 'allow_runtime_control_enable' in result.reason
