"""
Two of the three stop layers through a real node (the deadman is tested in test_fc_node).

stop_on_shutdown on SIGTERM, and the drive's own comms timeout when the node is killed.
"""

import signal
import time

from drive_bridge.sim.devices import make_sim_server
from drive_bridge.sim.fc_profile_model import TIMEOUT_STOP
import pytest
from ros_helpers import RosClient, start_node, stop_node, write_params

DEVICES = {
    'conv': {'family': 'fc', 'model': 'fc51', 'address': 1, 'poll_rate': 10.0,
             'speed_reference': 50.0, 'comms_timeout': 9.5,  # the keepalive rule: >= 8.46 s
             'comms_timeout_function': TIMEOUT_STOP},
    'main': {'family': 'mcd', 'model': 'mcd500', 'address': 20, 'stop_on_shutdown': False},
    'spare': {'family': 'mcd', 'model': 'mcd500', 'address': 21},
}
STOP_WORD, START = 0x043C, 1


@pytest.fixture
def sim():
    server = make_sim_server({1: 'fc51', 20: 'mcd500', 21: 'mcd500'},
                             settings={'fc': {'ramp_up_s': 0.2, 'ramp_down_s': 0.2},
                                       'mcd': {'start_time_s': 0.2}})
    server.open_pty()
    server.start()
    yield server
    server.stop()


def running_node(sim, tmp_path):
    params = write_params(tmp_path / 'safe_stop.yaml',
                          {'port': sim.pty_path, 'parity': 'N', 'timeout': 0.3}, DEVICES)
    process = start_node(params)
    client = RosClient(list(DEVICES), drives=['conv'])
    assert client.wait_state('conv', 'ready', 15.0), stop_node(process)
    assert client.wait_state('spare', 'ready', 15.0)
    for name in ('conv', 'main'):
        assert client.call(name, 'start').success
        assert client.wait_state(name, 'running')
    return process, client


def test_sigterm_stops_what_the_node_started_and_only_that(sim, tmp_path):
    process, client = running_node(sim, tmp_path)
    client.close()
    signalled = time.monotonic()
    process.send_signal(signal.SIGTERM)
    process.wait(timeout=10.0)
    took_s = time.monotonic() - signalled
    code, output = stop_node(process)
    print(f'SIGTERM to exit: {took_s * 1000:.0f} ms')
    assert code == 0, output
    assert 'shutdown: stop acknowledged by conv' in output
    drive = sim.devices[1].model
    assert drive.control_word == STOP_WORD
    assert list(sim.devices[20].model.commands_received)[-1] == START  # stop_on_shutdown off
    assert list(sim.devices[21].model.commands_received) == []  # never started by the node
    assert took_s < 5.0  # the stop is bounded by 3 s, then the node exits


def test_killed_node_leaves_the_stop_to_the_drives_comms_timeout(sim, tmp_path):
    process, client = running_node(sim, tmp_path)
    drive = sim.devices[1].model
    assert drive.timeout_s() == 9.5 and drive.timeout_function() == TIMEOUT_STOP
    client.close()
    process.kill()  # no clean shutdown: nothing more on the wire
    killed = time.monotonic()
    process.wait(timeout=10.0)
    stop_node(process)

    def drive_stopped_itself():
        with sim.lock:
            drive.advance(sim.clock())
            return drive.timeout_active and drive.output_pct == 0.0

    deadline = killed + 13.0
    while not drive_stopped_itself():
        assert time.monotonic() < deadline, 'the drive kept running without its master'
        time.sleep(0.05)  # polling the simulated drive's clock, not waiting for the node
    took_s = time.monotonic() - killed
    print(f'kill -9 to the drive stopped by its own timeout: {took_s * 1000:.0f} ms')
    assert drive.control_word != STOP_WORD  # nobody sent a stop: the drive did it
    assert 9.4 < took_s < 11.0
