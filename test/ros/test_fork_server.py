"""The fork server the ROS tier starts its commands from: a forked command is as an exec'd one."""

import os
import signal
import subprocess
import sys

import fork_server
import pytest
from safety_helpers import wait_for

pytestmark = pytest.mark.skipif(os.environ.get('DRIVE_BRIDGE_TEST_FORK') == '0',
                                reason='DRIVE_BRIDGE_TEST_FORK=0: every command is exec-ed')

CTL = [sys.executable, '-m', 'drive_bridge.ros.ctl.cli']


def threads(pid: int) -> int:
    """Return how many threads ``pid`` runs (DDS starts its own when rclpy initialises)."""
    with open(f'/proc/{pid}/status') as status:
        return int(next(line.split()[1] for line in status if line.startswith('Threads:')))


def both(command, **popen_kwargs):
    """Run ``command`` forked and exec'd; return (exit status, stdout, stderr) of each."""
    results = []
    for fork in (True, False):
        process = fork_server.ForkedPopen(command, stdout=subprocess.PIPE,
                                          stderr=subprocess.PIPE, text=True,
                                          stdin=subprocess.DEVNULL, fork=fork, **popen_kwargs)
        assert process.forked == fork
        stdout, stderr = process.communicate(timeout=60)
        results.append((process.returncode, stdout, stderr))
    return results


def test_a_forked_command_prints_and_exits_as_an_exec_d_one():
    for arguments in (['--help'], ['no-such-command'], ['--timeout', 'soon', 'state', 'x']):
        forked, execd = both(CTL + arguments)
        assert forked == execd, arguments


def test_a_forked_command_takes_the_environment_it_is_given():
    # rcl reads ROS_DOMAIN_ID through getenv at its init: 999 is out of range
    forked, execd = both(CTL + ['--timeout', '1', 'state', 'x'],
                         env={**os.environ, 'ROS_DOMAIN_ID': '999'})
    said = 'Calculated port number is too high'  # Fast DDS, with a timestamp
    assert forked[0] == execd[0] == 1
    assert said in forked[1] and said in execd[1], (forked, execd)


def test_a_forked_command_takes_the_directory_it_is_given(tmp_path):
    (tmp_path / 'bus.yaml').write_text('drive_bridge:\n  ros__parameters:\n    port: [\n')
    node = [sys.executable, '-m', 'drive_bridge.ros.node.entry', '--ros-args',
            '--params-file', 'bus.yaml']  # relative: found in the directory given
    forked, execd = both(node, cwd=tmp_path)
    assert forked == execd
    assert forked[0] == 2 and 'bus.yaml' in forked[2], forked


def test_a_forked_command_is_this_process_s_child_and_takes_its_signals():
    process = fork_server.ForkedPopen(
        CTL + ['--namespace', '/nowhere', '--timeout', '60', 'state', 'feeder'],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, stdin=subprocess.DEVNULL,
        preexec_fn=fork_server.default_signals)
    assert process.forked
    with open(f'/proc/{process.pid}/status') as status:
        parent = [line.split()[1] for line in status if line.startswith('PPid:')]
    assert parent == [str(os.getpid())]
    assert process.poll() is None
    assert wait_for(lambda: threads(process.pid) > 1, 30.0), 'rclpy never started'
    process.send_signal(signal.SIGINT)  # in its wait for the node
    stdout, stderr = process.communicate(timeout=30)
    assert process.returncode == 130, (stdout, stderr)
    assert 'Traceback' not in stderr, stderr
