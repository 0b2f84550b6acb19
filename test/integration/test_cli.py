"""The drive-bridge commissioning CLI against the simulators on a pty (no ROS)."""

import io

from drive_bridge.sim.devices import make_sim_server
from drive_bridge.tools.cli import main
import pytest
import yaml


@pytest.fixture(scope='module')
def line():
    server = make_sim_server({1: 'fc51', 5: 'vlt5000', 20: 'mcd500', 21: 'mcd3000'})
    server.open_pty()
    server.start()
    yield server
    server.stop()


def run(*argv):
    out = io.StringIO()
    code = main([str(arg) for arg in argv], out=out)
    return code, out.getvalue()


def bus(line):
    return ['--port', line.pty_path, '--parity', 'N', '--timeout', '0.1', '--quiet']


def test_scan_finds_each_device_with_family_and_model(line):
    code, out = run('scan', *bus(line), '--addresses', '1-22')
    assert code == 0
    assert 'address 1: fc fc51, state ready' in out
    assert 'address 5: vlt (VLT 5000/6000 option card' in out
    assert 'address 20: mcd mcd500, state ready' in out
    assert 'address 21: mcd mcd3000, state ready' in out
    assert '4 device(s) found at addresses 1-22' in out


def test_status_of_a_drive_and_of_a_starter(line):
    code, out = run('status', *bus(line), '--family', 'fc', '--address', 1)
    assert code == 0 and 'fc_1: fc fc51 at address 1' in out and 'state: ready' in out
    assert 'drive_type: FC-051' in out
    code, out = run('status', *bus(line), '--family', 'mcd', '--address', 20)
    assert code == 0 and 'mcd mcd500' in out and 'status word: 0x' in out


def test_get_and_set_with_conversion_and_units(line):
    code, out = run('get', *bus(line), '--family', 'fc', '--address', 1, '3-41')
    assert code == 0 and '3-41 = 3.0' in out and 'Ramp 1 Ramp-up Time' in out
    code, out = run('set', *bus(line), '--family', 'fc', '--address', 1, '3-41', '4.25')
    assert code == 0 and '3-41 = 4.25 (read back)' in out
    assert line.devices[1].model.parameters[341] == 425  # raw value, conversion index -2
    code, out = run('set', *bus(line), '--family', 'fc', '--address', 1, '3-41', '3')
    assert code == 0


def test_backup_restore_round_trip_with_verify(line, tmp_path):
    path = tmp_path / 'mcd500.yaml'
    code, out = run('backup', *bus(line), '--family', 'mcd', '--address', 20, path)
    assert code == 0 and 'parameters of mcd_20 saved' in out and 'verified' in out
    saved = yaml.safe_load(path.read_text())
    assert saved['model'] == 'mcd500' and len(saved['parameters']) == 591
    original = saved['parameters'][4]
    assert run('set', *bus(line), '--family', 'mcd', '--address', 20, 4, original + 5)[0] == 0
    code, out = run('restore', *bus(line), '--family', 'mcd', '--address', 20, path)
    assert code == 0 and '591 parameters restored to mcd_20 and verified' in out
    assert run('get', *bus(line), '--family', 'mcd', '--address', 20, 4)[1].strip() == \
        f'4 = {original}'


def test_monitor_prints_a_line_per_poll(line):
    code, out = run('monitor', *bus(line), '--family', 'fc', '--address', 1, '--count', 3,
                    '--period', 0.05)
    assert code == 0 and out.count('state: ready') == 3


def test_config_file_names_the_bus_and_device(line, tmp_path):
    params = tmp_path / 'line.yaml'
    params.write_text(yaml.safe_dump({'/**/drive_bridge': {'ros__parameters': {
        'port': line.pty_path, 'parity': 'N', 'devices': ['conv'],
        'conv': {'family': 'fc', 'model': 'fc51', 'address': 1}}}}))
    code, out = run('get', '--config', params, '--device', 'conv', '--quiet', '8-03')
    assert code == 0 and out.startswith('8-03 = ')


@pytest.mark.parametrize('argv, code, message', [
    (['get', '--family', 'fc', '--address', 1, '3-4x'], 2, "parameter number '3-4x'"),
    (['get', '--family', 'fc', '--address', 1, '99-99'], 2, 'give its data type'),
    (['set', '--family', 'fc', '--address', 1, '3-41', 'fast'], 2, 'takes a number'),
    (['set', '--family', 'fc', '--address', 1, '3-41', '3.333'], 2, 'not a multiple of 0.01'),
    (['scan', '--addresses', '40-2'], 2, 'must lie within 1-247, low to high'),
    (['status'], 2, 'name the device: --config FILE'),
    (['status', '--family', 'mcd', '--address', 150], 2, 'out of range for family mcd'),
    (['status', '--family', 'fc', '--address', 9], 1, 'no reply within 0.1 s'),
    (['restore', '--family', 'fc', '--address', 1, '/nonexistent.yaml'], 2, 'cannot read'),
])
def test_bad_arguments_get_one_clear_line(line, capsys, argv, code, message):
    got, _ = run(*argv, *bus(line))
    error = capsys.readouterr().err
    assert got == code, error
    assert error.startswith('drive-bridge: ') and message in error, error
    assert error.count('\n') == 1


def test_missing_port_is_a_bus_failure(capsys):
    assert run('status', '--port', '/dev/ttyNOPE', '--family', 'fc', '--address', 1)[0] == 1
    assert 'bus offline: /dev/ttyNOPE not found' in capsys.readouterr().err
