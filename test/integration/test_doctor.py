"""
``drive-bridge doctor`` and scan's hint against simulated adapters and a mis-set drive.

The simulator's adapter relay (:mod:`drive_bridge.sim.adapter`) stands in for the USB adapter
and the line: it echoes, batches like an FTDI latency timer, babbles, and lets bytes cross
only at the devices' baud rate and stop bits, as read from the master's pty.
"""

import io
import os
import subprocess
import sys
import time

from drive_bridge.sim.adapter import AdapterBehaviour, AdapterRelay, SerialSetting
from drive_bridge.sim.devices import make_sim_server
from drive_bridge.sim.fc_protocol_server import make_fc_protocol_server
from drive_bridge.tools.cli import main
from drive_bridge.tools.doctor_findings import FTDI_UDEV_RULE
from fake_sysfs import by_id, fake_sysfs
import pytest


@pytest.fixture
def line_with(request):
    """Return a function that serves devices behind an adapter relay; stopped afterwards."""
    started = []

    def serve(behaviour: AdapterBehaviour, fc_protocol: bool = False, models=None):
        models = models or {1: 'fc51'}
        server = make_fc_protocol_server(models) if fc_protocol else make_sim_server(models)
        relay = AdapterRelay(behaviour)
        path = relay.open_pty(server.open_pty())
        server.start()
        relay.start()
        started.append((server, relay))
        return path, relay

    yield serve
    for server, relay in started:
        relay.stop()
        server.stop()


def doctor(*argv):
    out = io.StringIO()
    code = main(['doctor', '--quiet', *[str(arg) for arg in argv]], out=out)
    return code, out.getvalue().splitlines()


def topic(lines, name):
    """Return the finding lines about ``name`` (``local echo``, ``address 3``)."""
    return [line for line in lines if line.split(None, 1)[1].startswith(f'{name}:')]


def test_an_echoing_adapter_is_found_and_the_search_still_finds_the_drive(line_with, tmp_path):
    port, _ = line_with(AdapterBehaviour(echo=True))
    code, lines = doctor('--port', port, '--address', 1, '--timeout', 1.0)
    assert topic(lines, 'local echo') == [
        'problem  local echo: the adapter echoes what it sends: set local_echo: true (or switch '
        'its echo off, if it has a switch)']
    assert topic(lines, 'address 1')[0].startswith('ok       address 1: fc fc51')
    assert code == 1 and lines[-1] == 'doctor: 1 device(s) found, 1 problem(s)'
    code, lines = doctor('--port', port, '--address', 1, '--timeout', 1.0, '--config',
                         echo_config(tmp_path, port))
    assert topic(lines, 'local echo')[0].startswith('ok       local echo: the adapter echoes')


def echo_config(folder, port):
    path = folder / 'echo.yaml'
    with open(path, 'w', encoding='utf-8') as file:
        file.write('/**/drive_bridge:\n  ros__parameters:\n    local_echo: true\n'
                   f'    port: "{port}"\n    devices: ["feeder"]\n'
                   '    feeder: {family: "fc", address: 1}\n')
    return path


def test_a_quiet_line_without_echo_is_healthy_and_exits_0(line_with):
    port, _ = line_with(AdapterBehaviour(device_line=SerialSetting(9600, 1)))
    code, lines = doctor('--port', port, '--address', 1, '--timeout', 1.0)
    assert code == 0, lines
    assert topic(lines, 'line')[0].startswith('ok       line: quiet')
    assert topic(lines, 'local echo') == [
        'ok       local echo: none (local_echo: false, as configured)']


def test_a_babbling_line_is_found(line_with):
    port, relay = line_with(AdapterBehaviour(babble_per_s=200.0))
    code, lines = doctor('--port', port, '--no-search', '--listen', 0.5)
    babble = topic(lines, 'line')
    assert babble and babble[0].startswith('problem  line: ') and \
        'while nobody was asked' in babble[0] and 'termination' in babble[0]
    assert relay.babbled_bytes > 0 and code == 1


def test_a_latency_timer_of_16_ms_is_found_with_the_udev_rule(line_with, tmp_path):
    port, _ = line_with(AdapterBehaviour(latency_s=0.016))
    sysfs = fake_sysfs(tmp_path / 'sys', port=port)
    dev = by_id(tmp_path / 'dev', port=os.path.realpath(port))
    code, lines = doctor('--port', port, '--address', 1, '--timeout', 1.0,
                         '--sysfs-root', sysfs, '--dev-root', dev)
    timer = topic(lines, 'latency timer')
    assert timer and timer[0].startswith('problem  latency timer: 16 ms') and \
        FTDI_UDEV_RULE in timer[0]
    assert topic(lines, 'name')[0].startswith('note     name: /dev/serial/by-id/usb-FTDI')
    assert topic(lines, 'adapter')[0] == 'ok       adapter: ttyUSB0: USB 0403:6001 FTDI ' \
        'FT232R USB UART (driver ftdi_sio)'
    assert topic(lines, 'address 1')[0].startswith('ok       address 1: fc fc51')  # batched
    assert code == 1


def test_a_drive_on_the_fc_protocol_at_9600_is_found_with_the_fix(line_with):
    # The FC 51 as delivered: FC protocol, 9600 8E1; the bridge asks Modbus RTU at 19200.
    port, relay = line_with(AdapterBehaviour(device_line=SerialSetting(9600, 1)),
                            fc_protocol=True, models={3: 'fc51'})
    code, lines = doctor('--port', port, '--baudrate', 19200, '--address', 3, '--timeout', 0.3)
    assert topic(lines, 'address 3') == [
        'problem  address 3: answers the FC protocol at 9600 baud, parity E (fc fc51, state '
        'ready): set 8-30 to Modbus RTU and 8-32 to 19200 baud, or set protocol: fc_protocol, '
        'baudrate: 9600']
    assert relay.dropped_bytes > 0  # the other baud rates were tried and heard nothing
    assert code == 1


def test_a_drive_at_another_baud_rate_is_found_with_the_fix(line_with):
    port, _ = line_with(AdapterBehaviour(device_line=SerialSetting(19200, 1)))
    code, lines = doctor('--port', port, '--address', 1, '--timeout', 0.5)
    assert topic(lines, 'address 1') == [
        'problem  address 1: answers Modbus RTU at 19200 baud, parity E (fc fc51, state ready): '
        'set 8-32 to 9600 baud, or set baudrate: 19200']


def test_a_named_address_that_never_answers_is_a_problem(line_with):
    port, _ = line_with(AdapterBehaviour(device_line=SerialSetting(9600, 1)))
    code, lines = doctor('--port', port, '--address', 7, '--baudrates', '9600', '--timeout',
                         0.2)
    assert topic(lines, 'address 7')[0].startswith('problem  address 7: no answer at any of')
    assert code == 1 and lines[-1] == 'doctor: 0 device(s) found, 1 problem(s)'


def test_a_missing_port_is_one_line(tmp_path):
    code, lines = doctor('--port', tmp_path / 'ttyUSB9')
    assert code == 1 and len(lines) == 1 and 'ttyUSB9 does not exist' in lines[0]


def test_a_gateway_protocol_is_refused_in_one_line(capsys):
    code, lines = doctor('--protocol', 'modbus_tcp', '--host', '127.0.0.1')
    error = capsys.readouterr().err
    assert code == 2 and lines == [] and error.count('\n') == 1 and 'serial port' in error


def test_scan_that_finds_nothing_searches_hints_and_exits_1(line_with):
    port, _ = line_with(AdapterBehaviour(device_line=SerialSetting(9600, 1)),
                        fc_protocol=True)
    out = io.StringIO()
    code = main(['scan', '--port', port, '--baudrate', '19200', '--addresses', '1-2',
                 '--timeout', '0.3', '--quiet'], out=out)
    lines = out.getvalue().splitlines()
    assert code == 1
    assert lines[0] == '0 device(s) found at addresses 1-2'
    assert any(line.startswith('problem  address 1: answers the FC protocol at 9600 baud')
               for line in lines), lines
    assert lines[-1].startswith('hint: ')


def test_scan_without_search_says_what_to_run(line_with):
    port, _ = line_with(AdapterBehaviour(device_line=SerialSetting(9600, 1)),
                        fc_protocol=True)
    out = io.StringIO()
    code = main(['scan', '--port', port, '--addresses', '1-1', '--timeout', '0.3', '--quiet',
                 '--no-search'], out=out)
    assert code == 1 and out.getvalue().splitlines() == [
        '0 device(s) found at addresses 1-1',
        f'hint: nothing answers at Modbus RTU at 9600 baud, parity E: run drive-bridge doctor '
        f'--port {port} --addresses 1-1 to check the port, the adapter and the line and to '
        'search other protocols, baud rates and parities (an FC 51 speaks the FC protocol as '
        'delivered)']


def test_latency_batches_reach_the_master_in_few_reads(line_with):
    port, _ = line_with(AdapterBehaviour(echo=True, latency_s=0.05))
    fd = os.open(port, os.O_RDWR | os.O_NOCTTY)
    try:
        os.set_blocking(fd, False)
        reads, received = 0, b''
        for index in range(40):  # a byte every 5 ms for 0.2 s: 40 bytes
            os.write(fd, bytes([0xF0]))
            time.sleep(0.005)
            reads, received = read_more(fd, reads, received)
        deadline = time.monotonic() + 5.0
        while len(received) < 40 and time.monotonic() < deadline:
            time.sleep(0.01)
            reads, received = read_more(fd, reads, received)
    finally:
        os.close(fd)
    assert received == bytes([0xF0]) * 40
    assert reads <= 12  # about one read per 50 ms batch; each byte alone without batches


def read_more(fd, reads, received):
    try:
        data = os.read(fd, 4096)
    except BlockingIOError:
        return reads, received
    return reads + 1, received + data


def test_the_simulator_options_make_the_adapter(tmp_path):
    link = str(tmp_path / 'ttySIM')
    sim = subprocess.Popen(
        [sys.executable, '-m', 'drive_bridge.sim.cli', '--protocol', 'fc_protocol', '--device',
         'fc51:3', '--device-line', '9600:E', '--echo', '--usb-latency', '16', '--link', link],
        stdout=subprocess.PIPE, stdin=subprocess.DEVNULL, text=True)
    try:
        shown = [sim.stdout.readline().strip() for _ in range(4)]
        assert shown[0] == 'adapter: echo, latency 16 ms, devices at 9600 baud, 1 stop bit(s)'
        assert shown[-1] == 'ready: fc51@3'
        code, lines = doctor('--port', link, '--baudrate', 19200, '--address', 3, '--timeout',
                             0.5)
    finally:
        sim.terminate()
        sim.wait(timeout=10)
    assert topic(lines, 'local echo')[0].startswith('problem  local echo: the adapter echoes')
    assert topic(lines, 'address 3')[0].startswith(
        'problem  address 3: answers the FC protocol at 9600 baud, parity E')
    assert code == 1
