"""
What a remote tool (ROS) may write, against the manuals: the pure rules, no I/O.

The issue 42 review's findings on the devices side: the control word timeout (FC 51 8-03,
8-04), the quick stop ramp (3-81) and the tables' other ramp and stop times, the MCD 3000's
local/remote setting (par. 20), and text a device cannot store (VLT 6000 par. 533).
"""

from drive_bridge.config import model as cfg
from drive_bridge.devices import fc51_parameters, mcd_parameters, vlt_parameters
from drive_bridge.devices import parameter_info as info
from drive_bridge.devices.parameters import (
    check_value, encode_value, FC_CONVERSION_FACTORS, TEXT, VLT_CONVERSION_FACTORS)
from drive_bridge.devices.remote_parameters import (
    remote_parameters, RemoteParameter, typed_value, write_refusal)
from drive_bridge.errors import CommandRefused
import pytest

FC = fc51_parameters.FC51_PARAMETERS
VLT6000 = vlt_parameters.VLT_PARAMETERS['vlt6000']


def remote(family: str, model: str):
    device = cfg.DeviceConfig(name='x', family=family, model=model, address=1, poll_rate=1.0,
                              allow_control=True, stop_on_shutdown=True, current_scale=1.0)
    profile = device.make_spec().profile
    factors = info.conversion_factors(profile)
    parameters = remote_parameters(info.parameter_table(profile), factors)
    return {parameter.name: parameter for parameter in parameters}, factors


def refusal(family: str, model: str, name: str, value) -> str:
    """Return why the ROS path refuses ``value`` before the bus ('' when it would write it)."""
    parameters, factors = remote(family, model)
    parameter = parameters[name]
    if parameter.read_only:
        return parameter.read_only
    typed, reason = typed_value(parameter, value)
    return reason or write_refusal(family, parameter.spec, typed) or \
        check_value(parameter.spec, typed, factors) or ''


def one_line(reason: str) -> bool:
    return bool(reason) and '\n' not in reason and len(reason) < 500


# -- FC 51 8-04: only the values that stop the motor when the bus goes silent ----------------
@pytest.mark.parametrize('value', [
    0,  # Off: the drive no longer stops when the bus goes silent
    1,  # Freeze output: the motor runs on; only coast, DC brake or an input stops it (5.6.2)
    3, 4,  # Jogging, Max. speed: the drive runs the motor
    6, 7, 8, 9, 10, 20, 26, 255,  # not FC 51 options we know (FC 102: 7-10 select a set-up)
])
def test_8_04_refuses_every_value_that_does_not_stop_the_motor(value):
    reason = refusal('fc', 'fc51', 'p8_04_control_word_timeout_function', value)
    assert one_line(reason), reason
    assert 'comms_timeout_function' in reason and 'commissioning' in reason, reason


@pytest.mark.parametrize('value', [2, 5])
def test_8_04_stop_and_stop_and_trip_are_written(value):
    assert refusal('fc', 'fc51', 'p8_04_control_word_timeout_function', value) == ''


def test_8_04_refusals_say_what_the_value_does():
    assert 'maximum speed' in write_refusal('fc', FC[804], 4)
    assert 'jog speed' in write_refusal('fc', FC[804], 3)
    assert 'Freeze output' in write_refusal('fc', FC[804], 1)
    assert 'Off' in write_refusal('fc', FC[804], 0)
    assert 'only 2 (Stop) and 5 (Stop and trip)' in write_refusal('fc', FC[804], 7)


def test_8_04_describes_what_ros_may_write():
    parameters, _ = remote('fc', 'fc51')
    constraints = parameters['p8_04_control_word_timeout_function'].constraints()
    assert 'from ROS only 2 (Stop) and 5 (Stop and trip)' in constraints, constraints


# -- FC 51 8-03: the configuration's range of comms_timeout --------------------------------
@pytest.mark.parametrize('value', [429496729.5, 6000.1, 0.0])
def test_8_03_is_held_to_the_range_of_comms_timeout(value):
    reason = refusal('fc', 'fc51', 'p8_03_control_word_timeout_time', value)
    assert one_line(reason) and 'comms_timeout' in reason, reason


@pytest.mark.parametrize('value', [0.1, 3.7, 6000.0])
def test_8_03_within_the_range_is_written(value):
    assert refusal('fc', 'fc51', 'p8_03_control_word_timeout_time', value) == ''


def test_8_03_range_is_described():
    parameters, _ = remote('fc', 'fc51')
    timeout = parameters['p8_03_control_word_timeout_time']
    assert (timeout.minimum, timeout.maximum) == (0.1, 6000.0)
    assert 'comms_timeout' in timeout.constraints()


def test_the_vlt_bus_timeout_parameters_are_not_offered_writable():
    # VLT 5000 par. 513/514 and VLT 6000 par. 555/556 (bus time interval and its function)
    # are in no table: not offered. If one is tabled, it needs the rule 8-03/8-04 have.
    for model, numbers in (('vlt5000', (513, 514)), ('vlt6000', (555, 556))):
        parameters, _ = remote('vlt', model)
        writable = {parameter.number for parameter in parameters.values()
                    if not parameter.read_only}
        assert not writable & set(numbers), (model, writable & set(numbers))


# -- ramp and stop times: the manual's range ----------------------------------------------
def test_3_81_quick_stop_ramp_time_has_the_manuals_range():
    spec = FC[381]
    assert (spec.minimum, spec.maximum, spec.unit) == (0.05, 3600.0, 's')
    assert 'Ramp times 0.05 - 3600' in spec.source
    reason = refusal('fc', 'fc51', 'p3_81_quick_stop_ramp_time', 42949672.95)
    assert one_line(reason) and 'above the maximum 3600 s' in reason, reason
    assert refusal('fc', 'fc51', 'p3_81_quick_stop_ramp_time', 0.04)
    assert refusal('fc', 'fc51', 'p3_81_quick_stop_ramp_time', 1.5) == ''


@pytest.mark.parametrize('table, factors', [
    (FC, FC_CONVERSION_FACTORS), (vlt_parameters.VLT_PARAMETERS['vlt5000'],
                                  VLT_CONVERSION_FACTORS), (VLT6000, VLT_CONVERSION_FACTORS)])
def test_every_writable_time_has_a_bounded_range(table, factors):
    # A time in seconds ROS may write (ramps, quick stop, timeouts, filters) is bounded by
    # a source, not only by its data type (3-81 took 497 days).
    for parameter in remote_parameters(table, factors):
        if parameter.read_only or parameter.spec.unit != 's':
            continue
        assert parameter.maximum <= 18000.0, (parameter.name, parameter.maximum)


# -- MCD 3000 par. 20: the starter stays on the network -----------------------------------
@pytest.mark.parametrize('value', [0, 1, 2, 3])
def test_mcd3000_local_remote_control_is_read_only_from_ros(value):
    reason = refusal('mcd', 'mcd3000', 'p20_local_remote_control', value)
    assert one_line(reason) and 'network' in reason, reason


@pytest.mark.parametrize('value', [0, 1, 3])
def test_mcd3000_par_20_other_than_2_is_refused_even_past_the_read_only_check(value):
    spec = mcd_parameters.MCD_PARAMETERS['mcd3000']['20'].spec()
    reason = write_refusal('mcd', spec, value)
    assert one_line(reason) and 'off the network' in reason, reason
    assert write_refusal('mcd', spec, 2) == ''


def test_mcd3000_par_20_is_never_written_by_a_restore():
    assert mcd_parameters.MCD_PARAMETERS['mcd3000']['20'].spec().serial_line


# -- text: what a device can store, refused before anything is queued ---------------------
@pytest.mark.parametrize('text', ['\u65e5\u672c', '\u20ac', 'a\x00b', '\x00'])
def test_text_a_device_cannot_store_is_refused_in_one_line(text):
    spec = VLT6000[533]
    reason = check_value(spec, text, VLT_CONVERSION_FACTORS)
    assert reason and one_line(reason) and 'Latin-1' in reason, reason
    assert refusal('vlt', 'vlt6000', 'p533_display_text_1', text) == reason
    with pytest.raises(CommandRefused, match='Latin-1') as error:
        encode_value(spec, text, VLT_CONVERSION_FACTORS)
    assert '\n' not in str(error.value)


@pytest.mark.parametrize('text', ['HELLO', 'caf\u00e9 \u00ff', ''])
def test_latin1_text_is_taken(text):
    assert check_value(VLT6000[533], text, VLT_CONVERSION_FACTORS) is None


def test_every_text_parameter_is_checked_the_same_way():
    texts = [parameter for parameter in remote('vlt', 'vlt6000')[0].values()
             if parameter.spec.data_type == TEXT]
    assert texts and all(isinstance(parameter, RemoteParameter) for parameter in texts)
    for parameter in texts:
        assert check_value(parameter.spec, '\u20ac', VLT_CONVERSION_FACTORS)
