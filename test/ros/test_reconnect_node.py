"""The node through twenty unplug/replug cycles of its serial adapter, and a drive power cycle."""

import time

from diagnostic_msgs.msg import DiagnosticStatus
from drive_bridge.sim.devices import make_device, make_sim_server
import pytest
from ros_helpers import RosClient, start_node, stop_node, write_params

# One worker runs this module's tests: its node, a module fixture, then starts once, not
# once on every worker that takes one of them.
pytestmark = pytest.mark.xdist_group('reconnect_node')

DEVICES = {
    'conv': {'family': 'fc', 'model': 'fc51', 'address': 1, 'poll_rate': 10.0,
             'comms_timeout': 3.7, 'comms_timeout_function': 2},
    'main': {'family': 'mcd', 'model': 'mcd500', 'address': 20, 'poll_rate': 5.0},
}
CONFIGURED_803 = 37  # 3.7 s in 0.1 s units
SPOILED_803 = 7


@pytest.fixture(scope='module')
def line(tmp_path_factory):
    link = str(tmp_path_factory.mktemp('dev') / 'ttyUSB_sim')
    server = make_sim_server({1: 'fc51', 20: 'mcd500'})
    server.open_pty(link)
    server.start()
    yield server, link
    server.stop()


@pytest.fixture(scope='module')
def node(line, tmp_path_factory):
    server, link = line
    params = write_params(tmp_path_factory.mktemp('params') / 'reconnect.yaml',
                          {'port': link, 'parity': 'N', 'timeout': 0.1, 'retries': 1,
                           'offline_after': 2, 'backoff_max': 0.5,
                           'diagnostics_period': 0.2}, DEVICES)
    process = start_node(params)
    client = RosClient(list(DEVICES), drives=['conv'])
    assert client.wait_state('conv', 'ready', 15.0), stop_node(process)
    yield client
    client.close()
    print(stop_node(process)[1])


def level(node, name):
    status = node.diagnostics(name)
    return status.level if status is not None else None


def parameter_803(server):
    with server.lock:
        return server.devices[1].model.parameters[803]


def test_twenty_unplug_replug_cycles_reported_on_state_and_diagnostics(line, node):
    server, _ = line
    assert node.spin_until(lambda: parameter_803(server) == CONFIGURED_803)
    recoveries = []
    for cycle in range(20):
        server.unplug()
        assert node.wait_state('conv', 'offline', 5.0), f'cycle {cycle + 1}: not offline'
        assert node.wait_state('main', 'offline', 5.0)
        node.messages['/diagnostics'].clear()
        assert node.spin_until(lambda: level(node, 'conv') == DiagnosticStatus.ERROR, 5.0)
        assert 'not found' in node.diagnostics('conv').message
        with server.lock:  # the drive forgot its comms timeout while the cable was out
            server.devices[1].model.parameters[803] = SPOILED_803
        back_at = time.monotonic()
        server.replug()
        assert node.wait_state('conv', 'ready', 5.0), f'cycle {cycle + 1}: no recovery'
        recoveries.append(time.monotonic() - back_at)
        assert node.wait_state('main', 'ready', 5.0)
        assert node.spin_until(lambda: parameter_803(server) == CONFIGURED_803, 5.0)
        node.messages['/diagnostics'].clear()
        assert node.spin_until(lambda: level(node, 'conv') == DiagnosticStatus.OK, 5.0)
    print(f'node recovery after replug, 20 cycles: median '
          f'{sorted(recoveries)[10] * 1000:.0f} ms, max {max(recoveries) * 1000:.0f} ms')
    assert max(recoveries) < 3.0


def test_drive_power_cycle_resends_set_up_and_never_restarts_the_motor(line, node):
    server, _ = line
    assert node.call('conv', 'start').success  # running, with the keepalive going
    assert node.wait_state('conv', 'running')
    server.power_off(1)
    assert node.wait_state('conv', 'offline', 5.0)
    assert node.state('main') == 'ready'  # the starter on the same line kept its state
    fresh = make_device('fc51')
    assert fresh.model.parameters[803] != CONFIGURED_803
    server.power_on(1, fresh)
    assert node.wait_state('conv', 'ready', 5.0)
    assert node.spin_until(lambda: parameter_803(server) == CONFIGURED_803, 5.0)
    polls = len(node.values('conv', 'status_word'))
    assert node.spin_until(lambda: len(node.values('conv', 'status_word')) > polls + 10, 5.0)
    # The run was lost with the link: the drive gets the stop word, never the run word back.
    received = list(fresh.model.control_words_received)
    assert received and set(received) == {0x043C}
    assert node.state('conv') == 'ready'
    assert node.call('conv', 'start').success and node.wait_state('conv', 'running')
    assert node.call('conv', 'coast_stop').success
