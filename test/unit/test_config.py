"""Unit tests of configuration validation: one clear line per bad value."""

import glob
import math
import os

from drive_bridge.config import model as config
from drive_bridge.config.node_parameters import check_parameters_block, declared_parameters
from drive_bridge.config.params_file import load_params_file, load_yaml_file
from drive_bridge.errors import ConfigError
from drive_bridge.ros.naming import status_name
import pytest
import yaml

GOOD_DEVICE = {'family': 'mcd', 'model': 'mcd500', 'address': 20}


def build(bus=None, devices=None):
    bus_values = {'devices': ['starter'], **(bus or {})}
    return config.build_config(bus_values, devices if devices is not None
                               else {'starter': dict(GOOD_DEVICE)})


def test_defaults_follow_the_contract():
    built = build()
    assert built.link.protocol == 'modbus_rtu' and built.link.parity == 'E'
    assert built.link.baudrate == 9600 and built.link.timeout_s == 0.5
    assert built.link.effective_stopbits == 1
    assert built.timing.retries == 2
    assert built.timing.frame_gap_s == pytest.approx(3.5 * 11 / 9600)
    device = built.devices[0]
    assert (device.poll_rate, device.allow_control, device.stop_on_shutdown) == (5.0, True, True)


def test_no_parity_means_two_stop_bits():
    assert build({'parity': 'N'}).link.effective_stopbits == 2


def test_int_is_accepted_for_a_double():
    built = build(devices={'starter': {**GOOD_DEVICE, 'poll_rate': 10}})
    assert built.devices[0].poll_rate == 10.0


@pytest.mark.parametrize('bus, device, message', [
    ({}, {'family': 'abc'}, "parameter 'starter.family' = 'abc' is invalid: allowed mcd"),
    ({}, {'model': 'mcd999'},
     "'starter.model' = 'mcd999' is invalid for family mcd: allowed auto, mcd201"),
    ({}, {'address': 150}, "'starter.address' = 150 is out of range for family mcd: allowed 1-99"),
    ({}, {'address': None}, "parameter 'starter.address' is required"),
    ({}, {'poll_rate': 0.0}, "'starter.poll_rate' = 0.0 is out of range: allowed [0.1, 100]"),
    ({}, {'poll_rate': math.nan}, 'must be a finite number'),
    ({}, {'allow_control': 'yes'}, "'starter.allow_control' = 'yes' has the wrong type"),
    ({'parity': False}, {}, 'write parity: "N" with quotes'),
    ({'parity': 'X'}, {}, "parameter 'parity' = 'X' is invalid: allowed N, E, O"),
    ({'baudrate': 9601}, {}, "parameter 'baudrate' = 9601 is invalid"),
    ({'protocol': 'ap_ascii'}, {}, "do not fit protocol 'ap_ascii': it is 8N1"),
    ({'protocol': 'ap_ascii', 'parity': 'N', 'timeout': 0.1}, {},
     "parameter 'timeout' = 0.1 is too short for protocol 'ap_ascii'"),
    ({'protocol': 'ap_ascii', 'parity': 'N'}, {'family': 'fc', 'model': 'auto'},
     "device 'starter' (family fc) cannot run on protocol 'ap_ascii'"),
    ({'protocol': 'canopen'}, {}, "parameter 'protocol' = 'canopen' is invalid"),
    ({'timeout': 0.0}, {}, "parameter 'timeout' = 0.0 is out of range"),
    ({'serial_engine': 'pymodbus'}, {}, "'serial_engine' = 'pymodbus' is invalid: allowed "
     "native (pymodbus's serial client was removed after 0.4"),
    ({'late_reply_guard': -0.1}, {}, "'late_reply_guard' = -0.1 is out of range: allowed [0, 10]"),
])
def test_bad_values_give_one_clear_line(bus, device, message):
    with pytest.raises(ConfigError) as error:
        build(bus, {'starter': {**GOOD_DEVICE, **device}})
    assert message in str(error.value)
    assert '\n' not in str(error.value)


MODULE_RANGE = ("'starter.address' = 32 is out of range: the MCD Modbus Module DIP switches "
                'give 1-31 (manual 000 Appendix B')


@pytest.mark.parametrize('protocol, device, message', [
    ('modbus_rtu', {'address': 32}, MODULE_RANGE),
    ('ap_ascii', {'address': 32}, MODULE_RANGE),
    ('modbus_rtu', {'model': 'auto', 'address': 32, 'mcd_interface': 'module'}, MODULE_RANGE),
    ('modbus_rtu', {'model': 'mcd202', 'address': 99, 'mcd_interface': 'module'},
     'set mcd_interface: remote_operator'),
    ('modbus_rtu', {'model': 'mcd3000', 'mcd_interface': 'module', 'address': 32},
     MODULE_RANGE),
    ('modbus_rtu', {'model': 'mcd3000', 'address': 100},
     "'starter.address' = 100 is out of range for family mcd: allowed 1-99"),
    ('modbus_rtu', {'mcd_interface': 'keypad'},
     "'starter.mcd_interface' = 'keypad' is invalid: allowed auto, module, remote_operator"),
])
def test_an_mcd_address_beyond_what_sets_it_is_refused(protocol, device, message):
    bus = {'protocol': protocol, 'parity': 'N'} if protocol == 'ap_ascii' else {}
    with pytest.raises(ConfigError) as error:
        build(bus, {'starter': {**GOOD_DEVICE, **device}})
    assert message in str(error.value)
    assert '\n' not in str(error.value)


@pytest.mark.parametrize('device', [
    {'address': 31}, {'address': 1},
    {'address': 99, 'mcd_interface': 'remote_operator'},
    {'model': 'mcd3000', 'address': 99},  # the MCD 3000 takes the Remote Operator's range
    {'model': 'auto', 'address': 40},  # a model not named may be an MCD 3000 (scan's probe)
])
def test_an_mcd_address_within_what_sets_it_is_taken(device):
    built = build(None, {'starter': {**GOOD_DEVICE, **device}})
    assert built.devices[0].address == device['address']


def test_the_late_reply_guard_is_the_protocol_s_own_unless_set():
    assert build().link.guard_s == 0.1  # Modbus RTU
    assert build({'late_reply_guard': 0.4}).link.guard_s == 0.4
    ascii_bus = {'protocol': 'ap_ascii', 'parity': 'N'}
    assert build(ascii_bus).link.guard_s == 0.25  # the MCD 3000's response time


def test_device_list_errors():
    with pytest.raises(ConfigError, match="'devices' is empty"):
        config.build_config({'devices': []}, {})
    with pytest.raises(ConfigError, match="'devices' is required"):
        config.build_config({}, {})
    with pytest.raises(ConfigError, match='is invalid: use a letter'):
        config.build_config({'devices': ['1bad']}, {})
    with pytest.raises(ConfigError, match='listed twice'):
        config.build_config({'devices': ['a', 'a']}, {'a': GOOD_DEVICE})
    with pytest.raises(ConfigError, match="is also the address of 'a'"):
        config.build_config({'devices': ['a', 'b']}, {'a': GOOD_DEVICE, 'b': GOOD_DEVICE})


def test_make_spec_builds_the_profile():
    spec = build().devices[0].make_spec()
    assert spec.unit == 20 and spec.profile.family == 'mcd'
    assert spec.profile.configured_model == 'mcd500'


CONFIG_DIR = os.path.join(os.path.dirname(__file__), '..', '..', 'config')
AGGREGATOR = 'diagnostic_aggregator.yaml'


@pytest.mark.parametrize('path', sorted(
    path for path in glob.glob(os.path.join(CONFIG_DIR, '*.yaml'))
    if not path.endswith(AGGREGATOR)))
def test_shipped_config_files_are_valid(path):
    with open(path) as stream:
        parameters = yaml.safe_load(stream)['/**/drive_bridge']['ros__parameters']
    names = parameters['devices']
    devices = {name: parameters.pop(name) for name in names}
    built = config.build_config(parameters, devices)
    assert [device.name for device in built.devices] == names
    for device in built.devices:
        device.make_spec()


@pytest.mark.parametrize('device, message', [
    ({'family': 'mcd', 'speed_reference': 10.0},
     "'starter.speed_reference' applies to families fc, vlt only, not mcd"),
    ({'family': 'fc', 'model': 'auto', 'address': 1, 'speed_reference': 200.0},
     "'starter.speed_reference' = 200.0 is out of range: allowed [-200, 200)"),
    ({'family': 'fc', 'address': 1, 'model': 'auto', 'speed_reference': math.nan},
     'must be a finite number'),
    ({'family': 'fc', 'address': 1, 'model': 'auto', 'comms_timeout_function': 6},
     "'starter.comms_timeout_function' = 6 is invalid: allowed -1, 0, 1, 2, 3, 4, 5"),
    ({'family': 'fc', 'address': 248, 'model': 'auto'},
     "'starter.address' = 248 is out of range: allowed [1, 247]"),
])
def test_drive_settings(device, message):
    with pytest.raises(ConfigError) as error:
        build({}, {'starter': {**GOOD_DEVICE, **device}})
    assert message in str(error.value)


def test_drive_config_sets_the_reference():
    built = build({}, {'starter': {'family': 'fc', 'address': 1, 'speed_reference': 40.0,
                                   'reference_timeout': 1.5}})
    spec = built.devices[0].make_spec()
    assert spec.reference_pct == 40.0 and spec.reference_timeout_s == 1.5
    assert spec.profile.reference_word(spec.reference_pct) == 0x1999


def test_aggregator_config_groups_every_drive_bridge_status():
    with open(os.path.join(CONFIG_DIR, AGGREGATOR)) as stream:
        parameters = yaml.safe_load(stream)['/**/analyzers']['ros__parameters']
    group = parameters['drives']
    assert group['type'] == 'diagnostic_aggregator/GenericAnalyzer'
    # Status names: 'drive_bridge: <device>', or '/<ns>/drive_bridge: <device>'
    # (ros/node/diagnostics).
    assert group['contains'] == ['drive_bridge: ']
    for name in (status_name('/drive_bridge', 'feeder'),
                 status_name('/line1/drive_bridge', 'feeder')):
        assert any(part in name for part in group['contains'])


# -- names the node refuses (drive-bridge --config refuses them the same way) ---------------
NODE_BLOCK = {'port': '/dev/ttyUSB0', 'parity': 'E', 'autostart': False,
              'use_sim_time': False, 'devices': ['starter', 'drive'],
              'starter': dict(GOOD_DEVICE),
              'drive.family': 'fc', 'drive.address': 1, 'drive.comms_timeout': 1.0,
              'qos_overrides': {'/diagnostics': {'publisher': {'depth': 5}}}}


def test_a_node_block_with_only_names_the_node_declares_passes():
    check_parameters_block(NODE_BLOCK)  # nested and flat device blocks, rclpy's own


@pytest.mark.parametrize('key, value, message', [
    ('baud_rate', 9600, "unknown parameter 'baud_rate': known bus parameters are protocol, "),
    ('starter.pollrate', 5.0, "unknown parameter 'starter.pollrate': a mcd device takes "),
    ('starter.comms_timeout', 1.0, "parameter 'starter.comms_timeout' applies to families fc, "
     'vlt only'),
    ('ap_nak_retries', 3, "parameter 'ap_nak_retries' applies to protocol ap_ascii only, not "
     'modbus_rtu'),
    ('other.family', 'mcd', "parameter 'other.family': 'other' is not a listed device "
     '(devices: starter, drive)'),
    ('drive.family', 'nope', "parameter 'drive.family' = 'nope' is invalid: allowed "),
    ('protocol', 'modbus', "parameter 'protocol' = 'modbus' is invalid: allowed "),
])
def test_a_node_block_is_refused_for_the_first_name_the_node_refuses(key, value, message):
    with pytest.raises(ConfigError) as raised:
        check_parameters_block(dict(NODE_BLOCK, **{key: value}))
    assert str(raised.value).startswith(message), raised.value


def test_the_node_declares_the_names_the_check_takes():
    declared = declared_parameters('modbus_rtu', {'drive': 'fc'})
    assert {'baudrate', 'autostart', 'use_sim_time', 'drive.comms_timeout'} <= declared
    assert not {'ap_nak_retries', 'address_format', 'drive.start_time'} & declared


# -- a parameters file means to drive-bridge what it means to the node ----------------------
@pytest.mark.parametrize('text, value', [
    ('N', False), ('n', False), ('Y', True), ('y', True),  # rcl's booleans, PyYAML's text
    ('no', False), ('on', True),  # booleans to both
    ('"N"', 'N'), ("'y'", 'y'), ('E', 'E'), ('Nn', 'Nn'),  # text to both
])
def test_a_parameters_file_is_read_with_rcl_s_types(tmp_path, text, value):
    # rcl_yaml_param_parser reads a plain N as false: the node refused `parity: N` while
    # drive-bridge --config read the same file as parity "N" and ran.
    path = tmp_path / 'line.yaml'
    path.write_text(f'/**/drive_bridge:\n  ros__parameters:\n    parity: {text}\n'
                    f'    devices: [{text}]\n')
    parameters = load_params_file(str(path))['/**/drive_bridge']
    assert parameters['parity'] == value and type(parameters['parity']) is type(value)
    assert parameters['devices'] == [value]


def read_plain(tmp_path, text):
    """Return the value of ``timeout: text`` in a parameters file, as drive-bridge reads it."""
    path = tmp_path / 'line.yaml'
    path.write_text(f'/**/drive_bridge:\n  ros__parameters:\n    timeout: {text}\n')
    return load_params_file(str(path))['/**/drive_bridge']['timeout']


# rcl_yaml_param_parser (parse.c get_value, rcl 9.2 = Jazzy): a plain scalar is an int64 if
# strtoll(text, base 0) takes all of it, else a double if strtod takes all of it without a
# range error, else text. PyYAML (YAML 1.1) needs a dot and a signed exponent for a float.
@pytest.mark.parametrize('text, value', [
    ('1e-1', 0.1),  # text to PyYAML (no dot)
    ('1.0e-1', 0.1),  # a float to both
    ('-2E3', -2000.0),  # text to PyYAML (no dot); a double to rcl, not an integer
    ('1.0e5', 100000.0),  # text to PyYAML (unsigned exponent)
    ('5E+0', 5.0),
    ('.5', 0.5),
    ('1.', 1.0),
    ('0x1p3', 8.0),  # strtod's hexadecimal form
    ('9223372036854775808', 9223372036854775808.0),  # past int64: strtoll fails, strtod reads
    ('08', 8.0),  # not octal to strtoll (base 0), a decimal to strtod
])
def test_a_plain_number_of_a_parameters_file_is_a_double_where_rcl_reads_one(
        tmp_path, text, value):
    read = read_plain(tmp_path, text)
    assert type(read) is float and read == value


@pytest.mark.parametrize('text, value', [
    ('10', 10), ('-3', -3), ('+5', 5), ('0x1A', 26), ('010', 8), ('-010', -8),
    ('9223372036854775807', 9223372036854775807),
])
def test_a_plain_integer_of_a_parameters_file_is_read_as_strtoll_reads_it(
        tmp_path, text, value):
    read = read_plain(tmp_path, text)
    assert type(read) is int and read == value


@pytest.mark.parametrize('text, check', [
    ('inf', math.isinf), ('-Infinity', lambda value: value == -math.inf),
    ('nan', math.isnan), ('.nan', math.isnan), ('-.inf', lambda value: value == -math.inf),
])
def test_a_plain_infinity_or_nan_is_a_double_as_to_rcl(tmp_path, text, check):
    read = read_plain(tmp_path, text)
    assert type(read) is float and check(read)


@pytest.mark.parametrize('text', [
    '1e999', '1e-400',  # strtod's range error
    '1_000', '0b101', '1:30', '2024-01-02',  # numbers or a date to PyYAML only
    '1e', 'e5', '0x', '"1e-1"', "'-2E3'", '!!str 5',  # not whole, quoted or tagged
])
def test_what_rcl_reads_as_text_is_text(tmp_path, text):
    read = read_plain(tmp_path, text)
    assert type(read) is str and read == text.strip('"\'').replace('!!str ', '')


def test_other_yaml_files_keep_yaml_s_own_types(tmp_path):
    path = tmp_path / 'backup.yaml'  # a backup's text value N stays the text N
    path.write_text('value: N\nother: y\n')
    assert load_yaml_file(str(path), 'the backup') == {'value': 'N', 'other': 'y'}


def test_a_key_of_a_parameters_file_is_a_name_as_rcl_reads_it(tmp_path):
    # rcl reads every key as a name; PyYAML read `on:` (and now `n:`) as a boolean key.
    path = tmp_path / 'line.yaml'
    path.write_text('/**/drive_bridge:\n  ros__parameters:\n    devices: ["on", "n"]\n'
                    '    on:\n      family: fc\n    n:\n      family: fc\n      address: 1\n'
                    '    1: 2\n')
    parameters = load_params_file(str(path))['/**/drive_bridge']
    assert parameters == {'devices': ['on', 'n'], 'on': {'family': 'fc'},
                          'n': {'family': 'fc', 'address': 1}, '1': 2}
