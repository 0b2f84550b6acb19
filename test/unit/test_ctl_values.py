"""drive_bridge_ctl without a node: names, typed parameter values, references, messages."""

import pytest

# rclpy is not in the pymodbus 3.6.9 venv (transport tiers only): skipped there.
values = pytest.importorskip('drive_bridge.ros.ctl.values', reason='ROS 2 (rclpy) from PyPI')
ctl = pytest.importorskip('drive_bridge.ros.ctl.cli', reason='ROS 2 (rclpy) from PyPI')

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue  # noqa: E402,I100
from rcl_interfaces.msg import ParameterType  # noqa: E402
from rclpy.parameter import parameter_value_to_python as python_of  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import String  # noqa: E402


@pytest.mark.parametrize('node, namespace, expected', [
    ('', '', ('/', 'drive_bridge')),
    ('/line1/drive_bridge', '', ('/line1', 'drive_bridge')),
    ('line1/drive_bridge/', '', ('/line1', 'drive_bridge')),
    ('', '/line1', ('/line1', 'drive_bridge')),
    ('', 'line1/', ('/line1', 'drive_bridge')),
    ('/a/b/other', '', ('/a/b', 'other')),
])
def test_node_name(node, namespace, expected):
    assert values.node_name(node, namespace) == expected


def test_a_bad_node_name_is_one_line():
    with pytest.raises(values.BadInput, match="'/line 1/drive_bridge' is not a node name: "):
        values.node_name('', '/line 1')


@pytest.mark.parametrize('name, namespace, expected', [
    ('feeder/start', '/', '/feeder/start'),
    ('feeder/start', '/line1', '/line1/feeder/start'),
    ('/line2/feeder/start', '/line1', '/line2/feeder/start'),
])
def test_resolve(name, namespace, expected):
    assert values.resolve(name, namespace, is_service=True) == expected


@pytest.mark.parametrize('name', ['feeder start', 'feeder//start', '9feeder/start', ''])
def test_resolve_refuses_what_is_no_name(name):
    with pytest.raises(values.BadInput, match='is not a service name: '):
        values.resolve(name, '/', is_service=True)


@pytest.mark.parametrize('text, expected', [('40', 40.0), ('-200', -200.0),
                                            ('199.99', 199.99), ('-0', 0.0)])
def test_reference_percent(text, expected):
    assert values.reference_percent(text) == expected


@pytest.mark.parametrize('text, reason', [
    ('abc', "'abc' is not a number"), ('', "'' is not a number"),
    ('nan', "'nan' is not a finite number"), ('-inf', "'-inf' is not a finite number"),
    ('200', 'out of range: allowed [-200, 200) %'), ('-200.5', 'out of range'),
])
def test_reference_percent_refuses_what_the_node_refuses(text, reason):
    with pytest.raises(values.BadInput) as refused:
        values.reference_percent(text)
    assert reason in str(refused.value) and str(refused.value).endswith('nothing sent')


@pytest.mark.parametrize('kind, text, expected', [
    (ParameterType.PARAMETER_DOUBLE, '40', 40.0),
    (ParameterType.PARAMETER_DOUBLE, '-1e-3', -0.001),
    (ParameterType.PARAMETER_INTEGER, '7', 7),
    (ParameterType.PARAMETER_BOOL, 'false', False),
    (ParameterType.PARAMETER_BOOL, 'True', True),
    (ParameterType.PARAMETER_STRING, 'N', 'N'),  # not YAML's false: the node says string
    (ParameterType.PARAMETER_STRING, '40', '40'),
    (ParameterType.PARAMETER_STRING_ARRAY, '[a, b]', ['a', 'b']),
    (ParameterType.PARAMETER_DOUBLE_ARRAY, '[1, 2.5]', [1.0, 2.5]),
    (ParameterType.PARAMETER_BOOL_ARRAY, '[true, False]', [True, False]),
    (ParameterType.PARAMETER_NOT_SET, '40', 40),  # no declared type: guessed as ros2 does
])
def test_parameter_values_take_the_declared_type(kind, text, expected):
    value = values.parameter_value('p', text, kind)
    assert value.type == kind or kind == ParameterType.PARAMETER_NOT_SET
    assert python_of(value) == expected and type(python_of(value)) is type(expected)


@pytest.mark.parametrize('kind, text, reason', [
    (ParameterType.PARAMETER_DOUBLE, 'abc', "p is a double: write a number, not 'abc'"),
    (ParameterType.PARAMETER_DOUBLE, 'nan', "p must be a finite number, not 'nan'"),
    (ParameterType.PARAMETER_INTEGER, '4.5', 'p is an integer: write a whole number, not '),
    (ParameterType.PARAMETER_BOOL, '1', "p is a bool: write true or false, not '1'"),
    (ParameterType.PARAMETER_BOOL, 'yes', 'p is a bool'),
    (ParameterType.PARAMETER_STRING_ARRAY, 'a', 'p is a string array: write [a, b, ...]'),
    (ParameterType.PARAMETER_INTEGER_ARRAY, '[1, x]', 'p is an integer: write a whole'),
    (ParameterType.PARAMETER_BYTE_ARRAY, '[1]', 'p is a byte array: not settable'),
])
def test_parameter_values_of_the_wrong_type_are_refused(kind, text, reason):
    with pytest.raises(values.BadInput) as refused:
        values.parameter_value('p', text, kind)
    assert str(refused.value).startswith(reason)


@pytest.mark.parametrize('kind, text, shown', [
    (ParameterType.PARAMETER_DOUBLE, '40', '40.0'),
    (ParameterType.PARAMETER_BOOL, 'false', 'false'),
    (ParameterType.PARAMETER_STRING, '', "''"),
    (ParameterType.PARAMETER_STRING_ARRAY, '[feeder, crusher]', '[feeder, crusher]'),
])
def test_format_value_as_it_is_written(kind, text, shown):
    assert values.format_value(values.parameter_value('p', text, kind)) == shown


def test_messages_print_as_ros2_topic_echo_prints_them():
    assert values.message_text(String(data='running')) == 'data: running\n---'
    array = DiagnosticArray(status=[DiagnosticStatus(
        level=DiagnosticStatus.ERROR, name='drive_bridge: feeder',
        values=[KeyValue(key='online', value='False')])])
    text = values.message_text(array)
    assert "- level: 2\n  name: 'drive_bridge: feeder'" in text
    assert "  - key: online\n    value: 'False'" in text
    joints = values.message_text(JointState(name=['left'], velocity=[1.5]))
    assert 'velocity:\n- 1.5' in joints and 'position: []' in joints


@pytest.mark.parametrize('argv, reason', [
    (['--timeout', '0', 'state', 'feeder'], '--timeout must be a positive number'),
    (['--timeout', 'x', 'state', 'feeder'], "argument --timeout: invalid float value: 'x'"),
    (['echo', 'feeder/state', '--count', '0'], '--count must be 1 or more'),
    (['reference', 'feeder', '10', '--rate', 'inf'], '--rate must be in (0, 1000] Hz'),
    (['param', 'set', 'feeder.poll_rate'], 'the following arguments are required: value'),
    (['lifecycle', 'set', '4'], 'give the transition by its label'),
    (['--node', '/a', '--namespace', '/b', 'state', 'x'], 'not allowed with argument'),
])
def test_command_line_errors_are_one_line(argv, reason):
    with pytest.raises(values.BadInput) as refused:
        ctl.parse_args(argv)
    assert reason in str(refused.value) and '\n' not in str(refused.value)


def test_options_go_before_or_after_the_command():
    before = ctl.parse_args(['--namespace', '/line1', '--timeout', '3', 'call', 'feeder/start'])
    after = ctl.parse_args(['call', 'feeder/start', '--namespace', '/line1', '--timeout', '3'])
    for args in (before, after):
        assert (args.bridge_namespace, args.bridge_node, args.timeout) == \
            ('/line1', 'drive_bridge', 3.0)
    assert ctl.parse_args(['state', 'x']).bridge_namespace == '/'
    assert ctl.parse_args(['reference', 'feeder', '-20']).percent == -20.0
