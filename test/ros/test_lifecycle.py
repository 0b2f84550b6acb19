"""The managed node: each lifecycle transition through rclpy clients, against the simulator."""

from drive_bridge.sim.devices import make_sim_server
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState, GetState
import pytest
import rclpy
from ros_helpers import LATCHED, RosClient, start_node, stop_node, write_params
from std_msgs.msg import String

DEVICES = {'conv': {'family': 'fc', 'model': 'fc51', 'address': 1, 'poll_rate': 10.0,
                    'speed_reference': 30.0}}
STOP_WORD = 0x043C


@pytest.fixture
def sim():
    server = make_sim_server({1: 'fc51'},
                             settings={'fc': {'ramp_up_s': 0.2, 'ramp_down_s': 0.2}})
    server.open_pty()
    server.start()
    yield server
    server.stop()


class Lifecycle:
    """ChangeState and GetState clients of the node."""

    def __init__(self, client: RosClient):
        self.node = client.node
        self.change = self.node.create_client(ChangeState, '/drive_bridge/change_state')
        self.get = self.node.create_client(GetState, '/drive_bridge/get_state')
        assert self.change.wait_for_service(timeout_sec=15.0)
        assert self.get.wait_for_service(timeout_sec=15.0)

    def _call(self, client, request):
        future = client.call_async(request)
        rclpy.spin_until_future_complete(self.node, future, timeout_sec=10.0)
        assert future.done(), 'the lifecycle service did not answer'
        return future.result()

    def state(self) -> str:
        return self._call(self.get, GetState.Request()).current_state.label

    def transition(self, transition_id: int = 0, label: str = '') -> bool:
        request = ChangeState.Request(transition=Transition(id=transition_id, label=label))
        return self._call(self.change, request).success


@pytest.fixture
def managed(sim, tmp_path):
    params = write_params(tmp_path / 'managed.yaml',
                          {'port': sim.pty_path, 'parity': 'N', 'timeout': 0.3,
                           'autostart': False, 'diagnostics_period': 0.2}, DEVICES)
    process = start_node(params)
    client = RosClient(list(DEVICES), drives=['conv'])
    lifecycle = Lifecycle(client)
    yield client, lifecycle, process
    client.close()
    print(stop_node(process)[1])


def diagnostics_seen(client):
    return bool(client.messages['/diagnostics'])


def test_transitions_and_what_each_state_allows(managed, sim):
    client, lifecycle, process = managed
    assert lifecycle.state() == 'unconfigured'
    # ros2/rclpy#1209: an id that is not valid now must be refused, not kill the node.
    assert not lifecycle.transition(Transition.TRANSITION_ACTIVATE)
    assert lifecycle.state() == 'unconfigured' and process.poll() is None
    assert not lifecycle.transition(label='no_such_transition')

    assert lifecycle.transition(Transition.TRANSITION_CONFIGURE)
    assert lifecycle.state() == 'inactive'
    assert client.spin_until(lambda: diagnostics_seen(client))  # reading the bus already
    assert client.spin_until(lambda: client.diagnostics('conv') is not None
                             and client.diagnostics('conv').message == 'ready')
    response = client.call('conv', 'start')
    assert not response.success and 'node is inactive' in response.message
    assert client.values('conv', 'state') == []  # device topics are silent while inactive
    assert list(sim.devices[1].model.control_words_received) == []

    assert lifecycle.transition(label='activate')
    assert client.wait_state('conv', 'ready')
    assert client.call('conv', 'start').success
    assert client.wait_state('conv', 'running')

    assert lifecycle.transition(Transition.TRANSITION_DEACTIVATE)  # stops what it started
    assert sim.devices[1].model.control_word == STOP_WORD
    # Nothing is reported while inactive: the latched state says 'unknown', not 'running' of
    # the motor just stopped, also to a subscriber that joins now.
    assert client.wait_state('conv', 'unknown')
    joined_late = []
    client.node.create_subscription(String, 'conv/state', joined_late.append, LATCHED)
    assert client.spin_until(lambda: joined_late) and joined_late[-1].data == 'unknown'
    response = client.call('conv', 'start')
    assert not response.success and 'inactive' in response.message

    assert lifecycle.transition(Transition.TRANSITION_CLEANUP)
    assert lifecycle.state() == 'unconfigured'
    client.messages['/diagnostics'].clear()
    assert not client.spin_until(lambda: diagnostics_seen(client), timeout_s=1.0)

    assert lifecycle.transition(Transition.TRANSITION_CONFIGURE)  # the port opens again
    assert lifecycle.transition(Transition.TRANSITION_ACTIVATE)
    assert client.spin_until(lambda: client.state('conv') == 'ready')
    assert lifecycle.transition(label='shutdown')
    assert lifecycle.state() == 'finalized'
    assert process.poll() is None  # finalized, still answering until SIGTERM


def test_configure_with_a_bad_parameter_fails_and_stays_unconfigured(sim, tmp_path):
    params = write_params(tmp_path / 'bad.yaml',
                          {'port': sim.pty_path, 'parity': 'N', 'autostart': False},
                          {'conv': {'family': 'fc', 'model': 'fc99', 'address': 1}})
    process = start_node(params)
    client = RosClient([])
    lifecycle = Lifecycle(client)
    assert not lifecycle.transition(Transition.TRANSITION_CONFIGURE)
    assert lifecycle.state() == 'unconfigured'
    client.close()
    code, output = stop_node(process)
    assert "configuration error: parameter 'conv.model' = 'fc99' is invalid" in output
