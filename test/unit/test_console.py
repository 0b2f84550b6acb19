"""The terminal commands: strict numbers, one-line refusals; the short repr of values; files."""

import math

from drive_bridge.config.params_file import load_yaml_file
from drive_bridge.console import parse_integer, parse_number
from drive_bridge.errors import ConfigError
from drive_bridge.settings import MAX_SHOWN_CHARACTERS, shown
import pytest


@pytest.mark.parametrize('text, expected', [
    ('12', 12), ('-2', -2), ('+7', 7), ('1.5', 1.5), ('.5', 0.5), ('5.', 5.0), ('1e3', 1000.0),
    ('-1E-3', -0.001), ('007', 7),
])
def test_plain_decimal_numbers_are_read(text, expected):
    value = parse_number(text)
    assert value == expected and type(value) is type(expected)


@pytest.mark.parametrize('text', ['nan', '-inf', 'Infinity', '1e400'])
def test_nan_and_infinity_are_read_for_the_caller_to_refuse(text):
    assert not math.isfinite(parse_number(text))


@pytest.mark.parametrize('text', ['1_5', '\uff14', '\u0664', ' 1', '1 ', '0x10', '', '4,5',
                                  '1.5.1', '1e', 'e3', '.', '+', '1e1.5', '\u00b2'])
def test_what_float_takes_but_no_one_types_is_refused_in_one_line(text):
    with pytest.raises(ValueError) as refused:
        parse_number(text)
    assert str(refused.value) == f'{text!r} is not a plain decimal number (write e.g. 12, ' \
        '-1.5 or 1e3)'


@pytest.mark.parametrize('text', ['1_0', '\uff14', '1.0', '1e3', ' 1', '', '0x10', '-'])
def test_an_integer_is_digits_with_an_optional_sign(text):
    with pytest.raises(ValueError, match='is not a whole number'):
        parse_integer(text)
    assert parse_integer('-12') == -12 and parse_integer('+3') == 3


def test_a_value_in_a_message_is_shortened():
    bomb = ['x'] * 9
    for _ in range(8):  # 9 ** 9 items if walked in full
        bomb = [bomb] * 9
    assert len(shown(bomb)) <= MAX_SHOWN_CHARACTERS and shown(bomb).endswith('...')
    assert len(shown('a' * 10_000)) <= MAX_SHOWN_CHARACTERS
    assert (shown('N'), shown(False), shown(1e-05), shown([1, 2])) == \
        ("'N'", 'False', '1e-05', '[1, 2]')


@pytest.mark.parametrize('content, expected', [
    (b'a: 1\n# F\xf6rderband\n',
     'is not UTF-8 text: byte 0xf6 at line 2, offset 8 (save it as UTF-8)'),
    (bytes(range(256)), 'is not UTF-8 text: byte 0x80 at line 2, offset 128 (save it as UTF-8)'),
    (b'a: 1\nb: [x]\x00\n', 'is not valid YAML at line 2: control character U+0000 at '
     'position 11 is not allowed'),
])
def test_a_file_that_is_no_yaml_text_is_refused_in_one_line(tmp_path, content, expected):
    path = tmp_path / 'line.yaml'
    path.write_bytes(content)
    with pytest.raises(ConfigError) as refused:
        load_yaml_file(str(path), 'the file')
    assert str(refused.value) == f'the file {expected}'


def _parser_of(module_name: str):
    """Return the argument parser of one of the package's terminal commands."""
    if module_name == 'drive_bridge.ros.record.cli':
        pytest.importorskip('rclpy')
    module = __import__(module_name, fromlist=['build_parser'])
    return module.build_parser()


@pytest.mark.parametrize('module_name, argv, reason', [
    ('drive_bridge.tools.cli', ['status', '--bogus'],
     'drive-bridge status: error: unrecognized arguments: --bogus (see drive-bridge status'),
    # An option before the command is the top parser's to refuse (status --help lists it).
    ('drive_bridge.tools.cli', ['--quiet', 'status'],
     'drive-bridge: error: unrecognized arguments: --quiet (see drive-bridge --help)'),
    ('drive_bridge.tools.cli', ['scan', '--family', 'fc'],
     'drive-bridge scan: error: unrecognized arguments: --family fc (see drive-bridge scan'),
    ('drive_bridge.tools.cli', ['set', '3-41'], 'the following arguments are required: value'),
    ('drive_bridge.tools.cli', ['frobnicate'], "invalid choice: 'frobnicate'"),
    ('drive_bridge.tools.cli', [], 'the following arguments are required: COMMAND'),
    ('drive_bridge.sim.cli', ['--nope'], 'unrecognized arguments: --nope'),
    ('drive_bridge.tools.plot_recording', [], 'the following arguments are required'),
    ('drive_bridge.ros.record.cli', ['--zz'], 'unrecognized arguments: --zz'),
])
def test_a_refused_command_line_is_one_line_and_exit_status_2(module_name, argv, reason,
                                                              capsys):
    parser = _parser_of(module_name)
    with pytest.raises(SystemExit) as exited:
        parser.parse_args(argv)
    captured = capsys.readouterr()
    assert exited.value.code == 2 and captured.out == ''
    lines = captured.err.splitlines()
    assert len(lines) == 1, captured.err
    assert reason in lines[0] and lines[0].endswith('--help)'), lines[0]
    assert 'usage:' not in captured.err


def test_a_parsed_command_line_carries_no_note_of_its_parser():
    from drive_bridge.tools.cli import build_parser
    parsed = build_parser().parse_args(['status', '--port', '/dev/null', '--family', 'fc',
                                        '--address', '1'])
    assert not any('parser' in key for key in vars(parsed)), vars(parsed)
