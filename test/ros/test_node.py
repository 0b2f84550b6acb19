"""The node in a subprocess against the simulator, driven through rclpy clients."""

import os

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from drive_bridge.sim.mcd_device import make_mcd_server
import pytest
from rcl_interfaces.msg import Parameter as ParameterMsg, ParameterType, ParameterValue
from rcl_interfaces.srv import SetParameters
import rclpy
from ros_helpers import (
    LATCHED, lean_node, node_output, RosClient, running_node, serving, spin_until, start_node,
    stop_node, write_params)
from std_msgs.msg import String

# One worker runs this module's tests: its node, a module fixture, then starts once, not
# once on every worker that takes one of them.
pytestmark = pytest.mark.xdist_group('node')

DEVICES = {
    'main': {'family': 'mcd', 'model': 'mcd500', 'address': 20, 'poll_rate': 10.0},
    'watch': {'family': 'mcd', 'model': 'auto', 'address': 21, 'poll_rate': 10.0,
              'allow_control': False},
    'dead': {'family': 'mcd', 'model': 'mcd500', 'address': 22, 'poll_rate': 10.0},
}


@pytest.fixture(scope='module')
def sim():
    with serving(make_mcd_server({20: 'mcd500', 21: 'mcd202'}, start_time_s=1.0,
                                 stop_time_s=1.0)) as server:
        yield server


@pytest.fixture(scope='module')
def node(sim, tmp_path_factory):
    with running_node(tmp_path_factory.mktemp('params') / 'bus.yaml',
                      {'port': sim.pty_path, 'parity': 'N', 'timeout': 0.2,
                       'backoff_max': 2.0, 'diagnostics_period': 0.5}, DEVICES,
                      ready=['main']) as client:
        # At rest before the first test: until 'dead' is offline each of its polls holds the
        # line for three attempts (timeout 0.2 s + the 0.1 s guard each), about 0.9 s, longer
        # than the 0.6 s the soft start's current stays above 300 A; a start sent then saw
        # no reading of the peak (a fresh-clone CI run). Offline, a probe holds it 0.3 s.
        assert client.wait_state('dead', 'offline', 15.0)
        yield client


def test_start_running_then_stop_ready(node, sim):
    response = node.call('main', 'start')
    assert response.success, response.message
    assert response.message == 'start acknowledged by main (address 20)'
    assert node.wait_state('main', 'running')
    assert node.spin_until(lambda: max(node.values('main', 'motor_current')) > 300), \
        node.values('main', 'motor_current')
    assert node.call('main', 'stop').success
    assert node.wait_state('main', 'ready')
    states = node.values('main', 'state')
    assert states[-4:] == ['starting', 'running', 'stopping', 'ready']
    assert node.spin_until(lambda: node.values('main', 'motor_temperature')[-1:] > [0])


def test_reset_after_injected_trip(node, sim):
    with sim.lock:
        sim.devices[20].model.trip(2, sim.clock())
    assert node.wait_state('main', 'tripped')
    assert node.spin_until(lambda: node.values('main', 'trip')[-1:] ==
                           ['Motor overload (thermal model)'])
    assert node.spin_until(lambda: node.values('main', 'trip_code')[-1:] == [2])
    refused = node.call('main', 'start')
    assert not refused.success and 'reset it first' in refused.message
    assert node.spin_until(lambda: (node.diagnostics('main') or DiagnosticStatus()).level ==
                           DiagnosticStatus.ERROR)
    assert node.call('main', 'reset').success
    assert node.wait_state('main', 'ready')
    assert node.spin_until(lambda: node.values('main', 'trip_code')[-1] == 0)
    assert node.spin_until(lambda: node.values('main', 'trip')[-1] == '')


def test_hand_on_refusal_with_reason(node, sim):
    sim.devices[20].model.hand_on = True
    try:
        response = node.call('main', 'start')
    finally:
        sim.devices[20].model.hand_on = False
    assert not response.success
    assert 'network control disabled (Hand On mode or par. 3-2)' in response.message
    assert 'Modbus error 09' in response.message


def test_offline_device(node):
    assert node.wait_state('dead', 'offline')
    response = node.call('dead', 'start')
    assert not response.success and 'offline' in response.message
    assert node.spin_until(lambda: node.diagnostics('dead') is not None and
                           node.diagnostics('dead').message.startswith('offline'))
    status = node.diagnostics('dead')
    assert status.level == DiagnosticStatus.ERROR
    assert node.values('dead', 'motor_current') == []  # never a stale number


def test_monitor_only_device(node, sim):
    assert node.wait_state('watch', 'ready')
    response = node.call('watch', 'start')
    assert not response.success and 'monitor only' in response.message
    assert list(sim.devices[21].model.commands_received) == []


def test_diagnostics_content(node):
    assert node.spin_until(lambda: node.diagnostics('main') is not None
                           and node.diagnostics('main').level == DiagnosticStatus.OK)
    status = node.diagnostics('main')
    assert status.hardware_id == 'mcd mcd500 address 20'
    values = {kv.key: kv.value for kv in status.values}
    for key in ('state', 'status_word', 'motor_current_a', 'transactions', 'errors_timeout',
                'rtt_avg_ms', 'last_error', 'product_type', 'serial_protocol_version'):
        assert key in values
    assert values['product_type'] == 'MCD 500'


def test_allow_control_set_at_runtime(node, sim):
    client = node.node.create_client(SetParameters, '/drive_bridge/set_parameters')
    assert client.wait_for_service(timeout_sec=5)
    parameter = ParameterMsg(name='main.allow_control', value=ParameterValue(
        type=ParameterType.PARAMETER_BOOL, bool_value=False))
    future = client.call_async(SetParameters.Request(parameters=[parameter]))
    rclpy.spin_until_future_complete(node.node, future, timeout_sec=5)
    assert future.result().results[0].successful
    before = len(sim.devices[20].model.commands_received)
    response = node.call('main', 'start')
    assert not response.success and 'monitor only' in response.message
    assert len(sim.devices[20].model.commands_received) == before
    parameter.value.bool_value = True
    future = client.call_async(SetParameters.Request(parameters=[parameter]))
    rclpy.spin_until_future_complete(node.node, future, timeout_sec=5)
    assert future.result().results[0].successful
    node.node.destroy_client(client)


@pytest.mark.parametrize('device, bus, expected', [
    ({'address': 150}, {}, "'main.address' = 150 is out of range for family mcd: allowed 1-99"),
    ({'family': 'nope'}, {}, "'main.family' = 'nope' is invalid: allowed mcd"),
    ({}, {'parity': False}, 'write parity: "N" with quotes'),
    ({'poll_rat': 3.0}, {}, "unknown parameter 'main.poll_rat'"),
    ({'poll_rate': 1e9}, {}, "'main.poll_rate' = 1000000000.0 is out of range: allowed [0.1, "),
    ({'poll_rate': 0.0}, {}, "'main.poll_rate' = 0.0 is out of range: allowed [0.1, 100]"),
    ({'poll_rate': float('nan')}, {}, "'main.poll_rate' = nan must be a finite number"),
    ({'address': 300}, {}, "'main.address' = 300 is out of range: allowed [1, 247]"),
    ({}, {'timeout': 0.001}, "'timeout' = 0.001 is out of range: allowed [0.02, 10]"),
    ({}, {'retries': 11}, "'retries' = 11 is out of range: allowed [0, 10]"),
    ({'comms_timeout': 1.0}, {}, "'main.comms_timeout' applies to families fc, vlt only"),
    ({}, {'baud_rate': 9600}, "unknown parameter 'baud_rate': known bus parameters are "),
])
def test_config_errors_stop_the_node_with_one_line(tmp_path, device, bus, expected):
    params = write_params(tmp_path / 'bad.yaml', {'port': '/dev/null', **bus},
                          {'main': {'family': 'mcd', 'address': 20, **device}})
    assert_one_line_config_error(start_node(params), expected)


@pytest.mark.parametrize('name', ['feeder\n', 'x' * 300, 'my-drive', 'my drive', '1drive'])
def test_an_invalid_device_name_is_named_as_such(tmp_path, name):
    params = write_params(tmp_path / 'bad.yaml', {'port': '/dev/null'},
                          {name: {'family': 'mcd', 'address': 20}})
    assert_one_line_config_error(start_node(params), f'device name {name!r} is invalid')


def test_a_file_rcl_cannot_parse_gets_one_line(tmp_path):
    params = write_params(tmp_path / 'bad.yaml', {'port': '/dev/null'},
                          {'': {'family': 'mcd', 'address': 20}})
    assert_one_line_config_error(start_node(params), 'ROS could not take the arguments: ')


def test_duplicate_keys_are_refused_with_their_lines(tmp_path):
    path = tmp_path / 'twice.yaml'
    path.write_text('/**/drive_bridge:\n  ros__parameters:\n    devices: ["main"]\n'
                    '    main:\n      family: mcd\n      address: 20\n'
                    '      allow_control: false\n      allow_control: true\n')
    assert_one_line_config_error(start_node(str(path)),
                                 "key 'allow_control' is given twice (lines 7 and 8)")


def assert_one_line_config_error(process, expected: str) -> None:
    """Check that the node exits 2 with one line, the configuration error, no traceback."""
    code = process.wait(timeout=20)
    stderr = node_output(process)
    assert code == 2, stderr
    lines = [line for line in stderr.splitlines() if 'configuration error' in line]
    assert len(lines) == 1 and expected in lines[0], stderr
    assert 'Traceback' not in stderr, stderr


def test_diagnostics_nobody_listened_to_begin_when_a_subscription_comes(tmp_path):
    # The node builds /diagnostics only while a subscription is matched: one that comes
    # later gets arrays from then on, each device in them. The topic is remapped: this
    # module's other node publishes /diagnostics to its own client meanwhile.
    topic = '/line3/diagnostics'
    watcher = lean_node(f'test_watcher_{os.getpid()}')
    try:
        with serving(make_mcd_server({20: 'mcd500'})) as server:
            params = write_params(tmp_path / 'quiet.yaml',
                                  {'port': server.pty_path, 'parity': 'N',
                                   'diagnostics_period': 0.5},
                                  {'solo': {'family': 'mcd', 'address': 20, 'poll_rate': 10.0}})
            process = start_node(params, namespace='/line3', remaps=[f'/diagnostics:={topic}'])
            try:
                states, arrays = [], []
                watcher.create_subscription(String, '/line3/solo/state',
                                            lambda message: states.append(message.data), LATCHED)
                assert spin_until(watcher, lambda: states[-1:] == ['ready']
                                  and watcher.count_publishers(topic) == 1, 15.0), \
                    node_output(process)
                assert watcher.count_subscribers(topic) == 0  # nobody has listened so far
                watcher.create_subscription(DiagnosticArray, topic, arrays.append, 10)
                # Discovery, then at most one period (0.5 s) to the next array.
                assert spin_until(watcher, lambda: len(arrays) >= 2, 10.0), node_output(process)
                assert {tuple(status.name for status in array.status) for array in arrays} == \
                    {('/line3/drive_bridge: solo',)}
            finally:
                stop_node(process)
    finally:
        watcher.destroy_node()


def test_sigterm_stops_the_motor_this_node_started(tmp_path):
    server = make_mcd_server({20: 'mcd500'}, start_time_s=0.5)
    server.open_pty()
    server.start()
    try:
        params = write_params(tmp_path / 'one.yaml', {'port': server.pty_path, 'parity': 'N'},
                              {'solo': {'family': 'mcd', 'address': 20, 'poll_rate': 10.0}})
        # exec'd, as a user starts it (the other tests fork it: test/fork_server.py)
        process = start_node(params, namespace='/line2', fresh=True)
        client = RosClient(['solo'], namespace='/line2')
        try:
            assert client.wait_state('solo', 'ready', 15.0)
            assert client.call('solo', 'start').success
            assert client.wait_state('solo', 'running')
        finally:
            client.close()
        code, stderr = stop_node(process)
        assert code == 0, stderr
        assert list(server.devices[20].model.commands_received) == [1, 2]  # start, stop
        assert 'stop acknowledged by solo' in stderr
    finally:
        server.stop()


def test_a_restarted_node_opens_the_simulator_s_pty_with_parity_e_and_logs_why(tmp_path):
    # Linux takes parity E on a pty once: the restarted node found the link offline with
    # "(22, 'Invalid argument')". The pty is opened without parity, and the log says so.
    with serving(make_mcd_server({20: 'mcd500'})) as server:
        for _ in range(2):
            with running_node(tmp_path / 'bus.yaml', {'port': server.pty_path, 'parity': 'E'},
                              {'main': {'family': 'mcd', 'address': 20}},
                              ready=['main']) as client:
                assert client.spin_until(lambda: 'is a pty' in node_output(client.process))
                assert client.wait_state('main', 'ready')
                log = node_output(client.process)
            notes = [line for line in log.splitlines() if 'is a pty' in line]
            assert len(notes) == 1 and '[INFO]' in notes[0], log
            assert 'offline' not in log, log
            assert notes[0].endswith(f'{server.pty_path} is a pty: opened without parity (a pty '
                                     'has no wire, so no parity); timing as configured, 9600 '
                                     'baud 8E1'), log


def test_the_nested_parameter_file_form_of_the_ros2_docs(tmp_path):
    server = make_mcd_server({20: 'mcd500'})
    server.open_pty()
    server.start()
    path = tmp_path / 'nested.yaml'
    path.write_text(f'line1:\n  drive_bridge:\n    ros__parameters:\n'
                    f'      port: "{server.pty_path}"\n      parity: "N"\n'
                    f'      devices: ["main"]\n      main:\n        family: mcd\n'
                    f'        address: 20\n')
    process = start_node(str(path), namespace='/line1')
    client = RosClient(['main'], namespace='/line1')
    try:
        assert client.wait_state('main', 'ready', 15.0), node_output(process)
    finally:
        client.close()
        stop_node(process)
        server.stop()


def test_enabling_control_at_runtime_is_logged_shown_and_can_be_forbidden(tmp_path):
    server = make_mcd_server({20: 'mcd500', 21: 'mcd500'})
    with serving(server):
        devices = {'main': {'family': 'mcd', 'address': 20, 'allow_control': False},
                   'aux': {'family': 'mcd', 'address': 21, 'allow_control': False}}
        # in a namespace of its own: the module's node runs a 'main' in the root namespace
        with running_node(tmp_path / 'p.yaml', {'port': server.pty_path, 'parity': 'N',
                                                'diagnostics_period': 0.2}, devices,
                          ready=['main'], namespace='/runtime') as client:
            assert client.set_parameter('main.allow_control', True).successful
            assert client.spin_until(
                lambda: client.diagnostics('main') is not None and 'allow_control_changed' in
                {kv.key for kv in client.diagnostics('main').values})
            assert client.spin_until(
                lambda: 'control ENABLED at runtime' in node_output(client.process))
        forbid = {'port': server.pty_path, 'parity': 'N', 'allow_runtime_control_enable': False}
        with running_node(tmp_path / 'q.yaml', forbid, devices, ready=['aux'],
                          namespace='/runtime') as client:
            result = client.set_parameter('aux.allow_control', True)
            assert not result.successful
            assert 'allow_runtime_control_enable is false' in result.reason
            assert not client.call('aux', 'start').success
            assert list(server.devices[21].model.commands_received) == []
