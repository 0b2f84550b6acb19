"""
The manual's command examples, run as written against the simulators (no ROS).

- ``<!-- test: drive-bridge against drive_bridge_sim OPTIONS -->``: the simulator the
  marker names stands in for ``/dev/ttyUSB0`` on its pty, with the page's framing as written
  (parity E); each ``drive-bridge`` command of the block runs with ``config/`` beside it and
  must print the ``#   `` lines under it. The commissioning page's writes are read back from
  the simulated devices.
- ``<!-- test: sim -->``: each ``drive_bridge_sim`` command starts and serves (its ``--link``
  paths and TCP ports replaced, so that test runs can share a machine), then ends on SIGTERM.
- ``<!-- test: parse -->``: each recording command parses with the command's own parser
  (test/ros/test_recording.py runs the commands).
The quick start runs in test/ros/test_quickstart.py.
"""

import io
import os
import shutil
import signal
import subprocess
import sys

from docs_helpers import all_blocks, ROOT, words
from drive_bridge.sim import cli as sim_cli
from drive_bridge.tools.cli import main as drive_bridge
from drive_bridge.tools.plot_recording import build_parser as plot_parser
import pytest

AGAINST = 'drive-bridge against drive_bridge_sim '
SIM_READY_S = 20.0


def marked(prefix: str) -> list:
    return [block for block in all_blocks() if block.marker.startswith(prefix)]


def simulated_port(marker: str):
    """Start the simulator the marker names on a pty; return (server, the pty's path)."""
    args = sim_cli.build_parser().parse_args(words(marker[len(AGAINST):]))
    server = sim_cli.build_server(args)
    path = server.open_pty()
    server.start()
    return server, path


@pytest.mark.parametrize('block', marked(AGAINST), ids=lambda block: block.where)
def test_every_drive_bridge_example_runs_as_written_against_the_simulator(block, tmp_path,
                                                                          monkeypatch):
    commands = block.commands()
    assert commands and all(command.startswith('drive-bridge ') for command, _ in commands)
    server, port = simulated_port(block.marker)
    try:
        shutil.copytree(os.path.join(ROOT, 'config'), tmp_path / 'config')
        for path in (tmp_path / 'config').glob('*.yaml'):
            path.write_text(path.read_text().replace('/dev/ttyUSB0', port))
        monkeypatch.chdir(tmp_path)
        for command, expected in commands:
            out = io.StringIO()
            code = drive_bridge(words(command.replace('/dev/ttyUSB0', port))[1:] + ['--quiet'],
                                out=out)
            assert code == 0, f'{block.where}: {command}\n{out.getvalue()}'
            for wanted in expected:
                assert wanted in out.getvalue(), \
                    f'{block.where}: {command}\n  printed:\n{out.getvalue()}\n  page: {wanted}'
    finally:
        server.stop()
    if block.page.endswith('cli.md'):  # the page's writes reached the devices
        assert server.devices[1].model.parameters[341] == 425
        assert server.devices[6].model.parameters[533] == '1234567890'


def test_the_commissioning_page_shows_every_command():
    shown = {words(command)[1] for block in marked(AGAINST) for command, _ in
             block.commands()}
    assert shown >= {'scan', 'status', 'get', 'set', 'backup', 'restore', 'monitor'}


def sim_commands() -> list:
    return [(block, command) for block in marked('sim') for command, _ in block.commands()]


def as_run_here(argv: list, tmp_path) -> list:
    """Return ``argv`` with its link paths and TCP ports made private to this test."""
    argv = list(argv)
    for index, word in enumerate(argv[:-1]):
        if word == '--link':
            argv[index + 1] = str(tmp_path / os.path.basename(argv[index + 1]))
        elif word == '--tcp':
            argv[index + 1] = '0'
    return argv


@pytest.mark.parametrize('block, command', sim_commands(),
                         ids=[f'{block.where}: {command[:60]}' for block, command in
                              sim_commands()])
def test_every_simulator_example_starts_as_written(block, command, tmp_path):
    argv = words(command)
    assert argv[0] == 'drive_bridge_sim'
    process = subprocess.Popen(
        [sys.executable, '-m', 'drive_bridge.sim.cli', *as_run_here(argv[1:], tmp_path)],
        stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        printed = []
        for line in process.stdout:  # its lines come flushed; it ends if it cannot start
            printed.append(line)
            if line.startswith('ready: '):
                break
        assert printed and printed[-1].startswith('ready: '), ''.join(printed)
        for index, word in enumerate(argv[:-1]):
            if word == '--link':
                assert os.path.islink(tmp_path / os.path.basename(argv[index + 1]))
    finally:
        process.send_signal(signal.SIGTERM)
        rest, _ = process.communicate(timeout=SIM_READY_S)
    assert process.returncode == 0, rest


def parse_commands() -> list:
    return [(block, command) for block in marked('parse') for command, _ in block.commands()]


@pytest.mark.parametrize('block, command', parse_commands(),
                         ids=[f'{block.where}: {command[:60]}' for block, command in
                              parse_commands()])
def test_every_recording_example_parses_with_its_command(block, command):
    argv = words(command)
    if argv[0] == 'drive_bridge_plot':
        parser = plot_parser()
    else:
        assert argv[0] == 'drive_bridge_record'
        record = pytest.importorskip('drive_bridge.ros.record.cli')  # rclpy: not in every venv
        parser = record.build_parser()
    parser.exit_on_error = False
    parser.parse_args(argv[1:])
