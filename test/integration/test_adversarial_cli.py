"""
Adversarial bad input to the drive-bridge CLI, beyond ``test_cli.py``'s tables.

Values that Python's ``float`` reads but no one would type as a number, numbers in
exponent notation, and files that are not UTF-8 text (a parameters file saved in Latin-1, a
binary file given as a backup). Each must end in one line on stderr with exit status 2, and
the simulated line must carry no write (read from the simulator's frame record).
"""

import contextlib
import io

from drive_bridge.protocol import rtu
from drive_bridge.sim.devices import make_sim_server
from drive_bridge.tools.cli import main
import pytest


WRITE_FUNCTIONS = (rtu.WRITE_SINGLE_COIL, rtu.WRITE_SINGLE_REGISTER, rtu.WRITE_MULTIPLE_COILS,
                   rtu.WRITE_MULTIPLE_REGISTERS)
FC51 = ['--family', 'fc', '--address', '1']
MCD500 = ['--family', 'mcd', '--address', '20']
HEAD = '/**/drive_bridge:\n  ros__parameters:\n'


@pytest.fixture
def line():
    server = make_sim_server({1: 'fc51', 20: 'mcd500'})
    server.open_pty()
    server.record_frames = True
    server.start()
    yield server
    server.stop()


def bus(line):
    return ['--port', line.pty_path, '--parity', 'N', '--baudrate', '115200', '--timeout',
            '1.0', '--quiet']


def run(*argv):
    """Run the CLI in this process; return (exit status, stderr); a traceback fails here."""
    error = io.StringIO()
    with contextlib.redirect_stderr(error):
        code = main([str(arg) for arg in argv], out=io.StringIO())
    return code, error.getvalue()


def writes(line):
    with line.lock:
        return [frame for frame in line.stats.frames if frame[1] in WRITE_FUNCTIONS]


def assert_one_line_refusal(code, error, expected=''):
    assert code == 2, error
    assert error.startswith('drive-bridge: ') and error.count('\n') == 1, error
    assert expected in error, error


@pytest.mark.parametrize('value', ['nan', 'inf', '1e400', '0x10', '', ' ', '4,5', '1.5.1',
                                   '1_5', '\uff14'])
def test_a_value_that_is_no_plain_number_is_refused_and_nothing_is_written(line, value):
    ramp = line.devices[1].model.parameters.get(341)
    code, error = run('set', *FC51, '3-41', value, *bus(line))
    print(f'{value!r}: {code} {error!r}')
    assert writes(line) == [] and line.devices[1].model.parameters.get(341) == ramp
    assert_one_line_refusal(code, error, 'nothing written')


def test_a_number_in_exponent_notation_gets_a_true_answer(line):
    code, error = run('set', *MCD500, '4', '1e3', *bus(line))
    print(f'{code} {error!r}')
    assert 'does not fit a 16-bit register' not in error, error
    assert code == 0 and len(writes(line)) == 1  # written as 1000, as '1000' is


def parameters_file(tmp_path, line, head=b''):
    path = tmp_path / 'line.yaml'
    path.write_bytes(head + (
        "/**/drive_bridge:\n  ros__parameters:\n    port: '%s'\n    parity: 'N'\n"
        '    baudrate: 115200\n    devices: [feeder]\n'
        '    feeder: {family: fc, model: fc51, address: 1}\n' % line.pty_path).encode())
    return path


def test_a_clean_parameters_file_works(line, tmp_path):
    """The control for the test below: the same file without the Latin-1 comment."""
    code, error = run('status', '--config', parameters_file(tmp_path, line), '--quiet')
    assert code == 0, error


def test_a_parameters_file_in_latin1_is_refused_in_one_line(line, tmp_path):
    path = parameters_file(tmp_path, line, '# Förderband Halle 2\n'.encode('latin-1'))
    code, error = run('status', '--config', path, '--quiet')
    assert_one_line_refusal(code, error, str(path))
    assert list(line.stats.frames) == []


def test_a_binary_file_given_to_restore_is_refused_in_one_line(line, tmp_path):
    path = tmp_path / 'feeder.yaml'
    path.write_bytes(bytes(range(256)))
    code, error = run('restore', *FC51, path, *bus(line))
    assert_one_line_refusal(code, error)
    assert writes(line) == []


@pytest.mark.parametrize('content, expected', [
    ('- a\n- b\n', 'must map a node name'),
    (HEAD + '    devices: [a]\n    devices: [b]\n',
     "key 'devices' is given twice"),
    (HEAD + '    devices: a\n    a: {family: fc}\n',
     "'devices'"),
    (HEAD + '    devices: [a]\n    a: [1, 2]\n', "'a."),
    (HEAD + '    devices: [a]\n    a: {family: fc, address: 1, poll_rate: .nan}\n', 'finite'),
    ('\x00\x01', 'is not valid YAML'),
])
def test_a_parameters_file_that_is_no_bus_is_refused_in_one_line(
        line, tmp_path, content, expected):
    path = tmp_path / 'params.yaml'
    path.write_text(content)
    code, error = run('status', '--config', path, '--quiet')
    print(error)
    assert_one_line_refusal(code, error, expected)
    assert list(line.stats.frames) == []


def test_a_directory_as_the_parameters_file(line, tmp_path):
    code, error = run('status', '--config', tmp_path, '--quiet')
    assert_one_line_refusal(code, error, 'cannot read the parameters file')


def test_no_read_command_of_the_cli_writes_to_a_monitor_only_device(line, tmp_path):
    """Monitor only writes nothing from any path: status, get, monitor and backup read only."""
    path = tmp_path / 'watch.yaml'
    path.write_text(HEAD + "    port: '%s'\n    parity: 'N'\n    baudrate: 115200\n"
                    '    devices: [watch, soft]\n'
                    '    watch: {family: fc, model: fc51, address: 1, allow_control: false}\n'
                    '    soft: {family: mcd, model: mcd500, address: 20, allow_control: false}\n'
                    % line.pty_path)
    for device, number in (('watch', '3-41'), ('soft', '4')):
        where = ['--config', path, '--device', device, '--quiet']
        for argv in (['status'], ['get', number], ['monitor', '--count', '2', '--period', '0.2'],
                     ['backup', tmp_path / f'{device}_backup.yaml']):
            code, error = run(argv[0], *where, *argv[1:])
            assert code == 0, (argv, error)
    assert writes(line) == []
    assert len(line.stats.frames) > 10  # they did talk to both devices


def test_an_alias_bomb_in_a_parameters_file_gets_a_short_line(tmp_path):
    anchors = ["&l0 ['x', 'x', 'x', 'x', 'x', 'x', 'x', 'x', 'x']"] + [
        f'&l{level} [' + ', '.join([f'*l{level - 1}'] * 9) + ']' for level in range(1, 6)]
    path = tmp_path / 'bomb.yaml'
    path.write_text(HEAD + "    port: /dev/null\n    parity: 'N'\n    devices: [a]\n"
                    '    a: {family: mcd, address: 1, poll_rate: [%s]}\n' % ', '.join(anchors))
    code, error = run('status', '--config', path, '--quiet')
    print(f'{len(path.read_bytes())} bytes of file: {len(error)} characters of error')
    assert_one_line_refusal(code, error, "'a.poll_rate'")
    assert len(error) < 1000, f'a {len(error)}-character line'
