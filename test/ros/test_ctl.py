"""
drive_bridge_ctl against the node in the namespace /line1, the motors read from the simulator.

Each command runs as a user runs it, in its own process; what it starts, stops or refuses
is judged by what the simulated devices received and do, not by what the command printed.
"""

import signal
import subprocess
import sys
import time
from typing import List

from drive_bridge.protocol.fc_profile_scaling import percent_to_word
from drive_bridge.sim.devices import make_sim_server
import fork_server
from integration_helpers import first_line_then_reader_gone
import pytest
from ros_helpers import running_node, serving
from safety_helpers import DriveProbe, is_run_word, McdProbe, wait_for, write_frames

# One worker runs this module's tests: its node, a module fixture, then starts once, not
# once on every worker that takes one of them.
pytestmark = pytest.mark.xdist_group('ctl')

NAMESPACE = '/line1'
DEVICES = {
    'feeder': {'family': 'fc', 'model': 'fc51', 'address': 1, 'poll_rate': 20.0,
               'speed_reference': 40.0},
    'watch': {'family': 'fc', 'model': 'fc51', 'address': 2, 'poll_rate': 10.0,
              'allow_control': False},
    'crusher': {'family': 'mcd', 'model': 'mcd500', 'address': 20, 'poll_rate': 10.0},
}
PROG = 'drive_bridge_ctl: '


def ctl(*args: str, where: List[str] = ('--namespace', NAMESPACE)) -> subprocess.CompletedProcess:
    """Run drive_bridge_ctl to its end, as a user does, for the node in /line1."""
    return fork_server.run([sys.executable, '-m', 'drive_bridge.ros.ctl.cli', *where, *args],
                           capture_output=True, text=True, timeout=60, stdin=subprocess.DEVNULL)


def assert_one_line(result: subprocess.CompletedProcess, status: int, expected: str) -> str:
    """Assert the exit status and a single stderr line that says ``expected``."""
    assert result.returncode == status, (result.returncode, result.stdout, result.stderr)
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith(PROG), result.stderr
    assert expected in lines[0], lines[0]
    return lines[0]


@pytest.fixture(scope='module')
def sim():
    server = make_sim_server({1: 'fc51', 2: 'fc51', 20: 'mcd500'},
                             settings={'fc': {'ramp_up_s': 1.0, 'ramp_down_s': 0.5},
                                       'mcd': {'start_time_s': 0.5, 'stop_time_s': 0.5}})
    server.record_frames = True  # every request, to show that nothing reached 'watch'
    with serving(server):
        yield server


@pytest.fixture(scope='module')
def line(sim, tmp_path_factory):
    with running_node(tmp_path_factory.mktemp('params') / 'line1.yaml',
                      {'port': sim.pty_path, 'parity': 'N', 'timeout': 0.3,
                       'diagnostics_period': 0.3}, DEVICES, drives=['feeder', 'watch'],
                      ready=list(DEVICES), namespace=NAMESPACE) as client:
        yield client


@pytest.fixture
def feeder(sim, line):
    """Yield the simulated FC 51 'feeder'; stop it and reset its parameters after the test."""
    probe = DriveProbe(sim, 1)
    yield probe
    assert line.set_parameter('feeder.reference_timeout', 0.0).successful
    assert line.set_parameter('feeder.speed_reference', 40.0).successful
    assert line.call('feeder', 'stop').success
    assert wait_for(probe.stopped)


def test_call_starts_and_stops_the_drive(feeder):
    started = ctl('call', 'feeder/start')
    assert started.returncode == 0, started.stderr
    assert started.stdout == ('success: true\n'
                              'message: start acknowledged by feeder (address 1)\n')
    assert wait_for(feeder.moving) and is_run_word(feeder.model.control_word)
    assert feeder.model.reference_word == percent_to_word(40.0)
    refused = ctl('param', 'set', 'feeder.allow_control', 'false')  # the node's own rule
    assert_one_line(refused, 1, 'allow_control cannot be set false while the bridge holds a '
                    'run command for feeder')
    stopped = ctl('call', 'feeder/stop')
    assert stopped.returncode == 0 and stopped.stdout.startswith('success: true\n')
    assert wait_for(feeder.stopped)


def test_a_refused_start_exits_1_with_the_reason(sim, line):
    crusher = McdProbe(sim, 20)
    sim.devices[20].model.hand_on = True
    try:
        result = ctl('call', 'crusher/start')
    finally:
        sim.devices[20].model.hand_on = False
    assert result.returncode == 1, result.stderr
    assert result.stdout.startswith('success: false\nmessage: rejected by crusher: network '
                                    'control disabled (Hand On mode or par. 3-2)')
    assert not crusher.moving()


def test_monitor_only_a_start_and_a_reference_write_nothing(sim, line):
    result = ctl('call', 'watch/start')
    assert result.returncode == 1
    assert result.stdout == ('success: false\n'
                             'message: watch is monitor only (allow_control is false): '
                             'nothing sent\n')
    published = ctl('reference', 'watch', '30')
    assert published.returncode == 0, published.stderr
    assert line.spin_until(lambda: _value(line, 'watch', 'rejected_references') == '1')
    assert write_frames(sim, 2) == []  # not one write to the monitor-only drive, ever
    assert not DriveProbe(sim, 2).moving()


def _value(line, device: str, key: str) -> str:
    status = line.diagnostics(device)
    values = {item.key: item.value for item in status.values} if status else {}
    return values.get(key, '')


def test_reference_once_reaches_the_running_drive(feeder):
    assert ctl('call', 'feeder/start').returncode == 0
    result = ctl('reference', 'feeder', '25')
    assert result.returncode == 0, result.stderr
    assert result.stdout == 'published 25 % on /line1/feeder/speed_reference (received by ' \
        'the node)\n'
    assert wait_for(lambda: feeder.model.reference_word == percent_to_word(25.0))
    assert wait_for(lambda: abs(feeder.model.output_pct - 25.0) < 0.01)


def test_a_reference_stream_until_ctrl_c_then_the_deadman_stops_the_drive(feeder):
    assert ctl('param', 'set', 'feeder.reference_timeout', '1').stdout == \
        'feeder.reference_timeout = 1.0 (double)\n'
    stream = fork_server.ForkedPopen(
        [sys.executable, '-m', 'drive_bridge.ros.ctl.cli', '--namespace', NAMESPACE, 'reference',
         'feeder', '-20', '--rate', '20'], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        text=True, stdin=subprocess.DEVNULL,
        preexec_fn=fork_server.default_signals)
    try:
        assert stream.stdout.readline() == \
            'publishing -20 % on /line1/feeder/speed_reference at 20 Hz until Ctrl-C\n'
        assert ctl('call', 'feeder/start').returncode == 0
        assert wait_for(lambda: feeder.model.reference_word == percent_to_word(-20.0))
        assert wait_for(lambda: feeder.model.output_pct < -19.99)
        assert is_run_word(feeder.model.control_word)  # the stream holds the drive running
        stream.send_signal(signal.SIGINT)
        out, err = stream.communicate(timeout=20)
    finally:
        if stream.poll() is None:
            stream.kill()
            stream.wait()
    assert stream.returncode == 0, err
    assert out.startswith('stopped after ') and 'reference_timeout' in out, out
    assert wait_for(feeder.stopped)  # the node's deadman, reference_timeout after the stream


def test_parameters_are_typed_as_the_node_declares_them(line):
    assert ctl('param', 'set', 'feeder.poll_rate', '10').stdout == \
        'feeder.poll_rate = 10.0 (double)\n'
    assert ctl('param', 'get', 'feeder.poll_rate').stdout == \
        'feeder.poll_rate = 10.0 (double)\n'  # still a double at the node, not an integer
    assert ctl('param', 'set', 'feeder.stop_on_shutdown', 'False').stdout == \
        'feeder.stop_on_shutdown = false (bool)\n'
    assert ctl('param', 'set', 'feeder.stop_on_shutdown', 'true').returncode == 0
    assert_one_line(ctl('param', 'set', 'feeder.poll_rate', '500'), 1,
                    'feeder.poll_rate = 500.0 refused by /line1/drive_bridge: ')
    listed = ctl('param', 'list', 'crusher.').stdout.splitlines()
    assert 'crusher.address = 20 (integer)' in listed
    assert 'crusher.allow_control = true (bool)' in listed
    assert all(name.startswith('crusher.') for name in listed)
    described = ctl('param', 'describe', 'feeder.speed_reference').stdout
    assert described.startswith('feeder.speed_reference (double)\n')
    assert 'allowed [-200, 200)' in described


def test_state_and_echo(line):
    assert ctl('state', 'crusher').stdout == 'ready\n'
    echoed = ctl('echo', 'crusher/motor_current', '--count', '2')
    assert echoed.returncode == 0, echoed.stderr
    assert echoed.stdout == 'data: 0.0\n---\n' * 2
    assert ctl('echo', 'watch/trip', '--count', '1').stdout == "data: ''\n---\n"  # latched
    diagnostics = ctl('echo', '/diagnostics', '--count', '1').stdout
    assert "name: '/line1/drive_bridge: crusher'" in diagnostics
    assert 'hardware_id: mcd mcd500 address 20' in diagnostics


def test_a_reader_that_goes_away_ends_echo_quietly(line):
    """`drive_bridge_ctl echo ... | head -1`: exit 141 as SIGPIPE would, no traceback."""
    echo = fork_server.ForkedPopen(
        [sys.executable, '-m', 'drive_bridge.ros.ctl.cli', '--namespace', NAMESPACE, 'echo',
         'crusher/motor_current'], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        stdin=subprocess.DEVNULL)
    ended = first_line_then_reader_gone(echo, timeout_s=30)
    assert ended.first_line == 'data: 0.0\n'
    assert ended.status == 141, ended
    assert 'Traceback' not in ended.stderr and 'Exception' not in ended.stderr, ended.stderr


def test_lifecycle_by_label(feeder):
    assert ctl('lifecycle', 'get').stdout == 'active\n'
    assert ctl('lifecycle', 'list').stdout == 'deactivate\nshutdown\n'
    assert_one_line(ctl('lifecycle', 'set', 'activate'), 1, 'cannot activate: '
                    '/line1/drive_bridge is active (possible now: deactivate, shutdown)')
    assert ctl('call', 'feeder/start').returncode == 0
    assert wait_for(feeder.moving)
    try:
        deactivated = ctl('lifecycle', 'set', 'deactivate')
        assert deactivated.stdout == 'deactivate: done, /line1/drive_bridge is inactive\n'
        assert feeder.last_write_stops()  # deactivate stopped the motor it had started
        assert wait_for(feeder.stopped)
        feeder.forget()
        refused = ctl('call', 'feeder/start')
        assert refused.returncode == 1 and 'node is inactive' in refused.stdout
        assert feeder.start_edges() == 0
    finally:
        activated = ctl('lifecycle', 'set', 'activate')
    assert activated.stdout == 'activate: done, /line1/drive_bridge is active\n'


@pytest.mark.parametrize('args, expected', [
    (['call', 'feeder/launch'], '/line1/drive_bridge has no service /line1/feeder/launch '
     '(its Trigger services: crusher/quick_stop, crusher/reset, crusher/start, '),
    (['call', 'drive_bridge/get_state'], 'is a lifecycle_msgs/srv/GetState service, not a '
     'Trigger'),
    (['call', 'feeder start'], "'feeder start' is not a service name"),
    (['reference', 'crusher', '10'], 'takes no speed reference on '
     '/line1/crusher/speed_reference (its drives: feeder, watch)'),
    (['reference', 'feeder', 'abc'], "speed reference 'abc' is not a number"),
    (['reference', 'feeder', 'nan'], "speed reference 'nan' is not a finite number"),
    (['reference', 'feeder', '200'], 'speed reference 200 % is out of range: allowed '
     '[-200, 200) %; nothing sent'),
    (['reference', 'feeder', '10', '--rate', '0'], '--rate must be in (0, 1000] Hz'),
    (['state', 'nothing'], "has no device 'nothing' (its devices: crusher, feeder, watch)"),
    (['param', 'set', 'feeder.speed_reference', 'abc'],
     "feeder.speed_reference is a double: write a number, not 'abc'"),
    (['param', 'set', 'feeder.allow_control', '1'],
     "feeder.allow_control is a bool: write true or false, not '1'"),
    (['param', 'set', 'feeder.poll_rate', 'inf'], 'feeder.poll_rate must be a finite number'),
    (['param', 'set', 'feeder.address', '3'], 'feeder.address is read-only'),
    (['param', 'get', 'feeder.speed_referenc'], "no parameter 'feeder.speed_referenc': did "
     'you mean feeder.speed_reference'),
    (['lifecycle', 'set', '3'], 'give the transition by its label'),
    (['lifecycle', 'set', 'activat'], "unknown transition 'activat'"),
    (['frobnicate'], "invalid choice: 'frobnicate'"),
])
def test_bad_input_exits_2_with_one_line(line, args, expected):
    result = ctl(*args)
    assert_one_line(result, 2, expected)
    assert result.stdout == ''


def timed_ctl(*args: str) -> tuple:
    """Run drive_bridge_ctl without --node or --namespace; return (result, seconds taken)."""
    started = time.monotonic()
    result = fork_server.run([sys.executable, '-m', 'drive_bridge.ros.ctl.cli', '--timeout',
                              str(SLOW_TIMEOUT_S), *args], capture_output=True, text=True,
                             timeout=3 * SLOW_TIMEOUT_S, stdin=subprocess.DEVNULL)
    return result, time.monotonic() - started


# A full name without --namespace waited --timeout for /drive_bridge, the default node, while
# the name said /line1. With a long --timeout, a run that ends well before it did not wait.
SLOW_TIMEOUT_S = 60.0


def test_full_names_without_a_namespace_find_the_node_at_once(feeder):
    started, seconds = timed_ctl('call', '/line1/feeder/start')
    assert started.returncode == 0, started.stderr
    assert started.stdout.startswith('success: true\n') and seconds < SLOW_TIMEOUT_S / 2
    assert wait_for(feeder.moving)  # the simulated drive runs
    stopped, _ = timed_ctl('call', '/line1/feeder/stop')
    assert stopped.returncode == 0 and wait_for(feeder.stopped)
    state, seconds = timed_ctl('state', '/line1/crusher')
    assert state.stdout == 'ready\n' and seconds < SLOW_TIMEOUT_S / 2
    echoed, seconds = timed_ctl('echo', '/diagnostics', '--count', '1')
    assert "name: '/line1/drive_bridge: " in echoed.stdout and seconds < SLOW_TIMEOUT_S / 2


@pytest.mark.parametrize('args, expected', [
    (['call', '/line1/feeder/launch'], 'no bridge node has /line1/feeder/launch (the Trigger '
     'services of /line1/drive_bridge: /line1/crusher/quick_stop, /line1/crusher/reset, '),
    (['call', '/line1/drive_bridge/feeder/start'], 'no bridge node has '
     '/line1/drive_bridge/feeder/start (the Trigger services of /line1/drive_bridge: '),
    (['state', '/line1/nothing'], 'no bridge node has /line1/nothing/state (the state topics '
     'of /line1/drive_bridge: /line1/crusher/state, /line1/feeder/state, /line1/watch/state)'),
])
def test_a_full_name_no_bridge_has_fails_at_once_naming_what_there_is(sim, line, args,
                                                                      expected):
    feeder = DriveProbe(sim, 1)
    assert wait_for(feeder.stopped)
    feeder.forget()
    result, seconds = timed_ctl(*args)
    assert_one_line(result, 2, expected)
    assert result.stdout == '' and seconds < SLOW_TIMEOUT_S / 2
    assert feeder.start_edges() == 0  # no start reached the drive


def test_a_service_under_the_node_name_is_answered_with_the_name_meant(line):
    result = ctl('call', '/line1/drive_bridge/feeder/start')
    assert_one_line(result, 2, '/line1/drive_bridge has no service '
                    '/line1/drive_bridge/feeder/start (its Trigger services: ')
    assert result.stderr.endswith('service names do not include the node name, did you mean '
                                  '/line1/feeder/start?\n')


def test_no_node_is_one_line_that_names_what_is_there(line):
    # default: /drive_bridge. 3 s: the command discovers /line1/drive_bridge within them
    # (with eight test workers on two cores, 1 s was once too short for its discovery)
    result = ctl('--timeout', '3', 'state', 'feeder', where=[])
    assert_one_line(result, 2, 'no node /drive_bridge within 3 s (ROS_DOMAIN_ID ')
    assert 'has /line1/drive_bridge: choose with --node' in result.stderr


# drive_bridge_ctl whose teardown never ends (rclpy.try_shutdown replaced by a long sleep),
# with a teardown limit of 1 s.
HANGING_TEARDOWN = """
import sys
import time

import rclpy
from drive_bridge.ros.ctl import cli as ctl

ctl.TEARDOWN_LIMIT_S = 1
rclpy.try_shutdown = lambda: time.sleep(60)
sys.exit(ctl.main(sys.argv[1:]))
"""


def test_a_teardown_that_hangs_is_ended_by_the_alarm_after_the_command_s_output():
    started = time.monotonic()
    result = subprocess.run([sys.executable, '-c', HANGING_TEARDOWN, '--namespace', '/nowhere',
                             '--timeout', '0.5', 'state', 'feeder'],
                            capture_output=True, text=True, timeout=30, stdin=subprocess.DEVNULL)
    seconds = time.monotonic() - started
    assert result.returncode == -signal.SIGALRM, (result.returncode, result.stderr)
    assert_one_line(result, -signal.SIGALRM, 'no node /nowhere/drive_bridge within 0.5 s')
    assert seconds < 20  # the sleep would take 60 s
