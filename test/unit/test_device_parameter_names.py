"""Device parameters as ROS parameters, the pure part: names, types, ranges, what is refused."""

from drive_bridge.devices import fc51_parameters, mcd_parameters, parameter_info, vlt_parameters
from drive_bridge.devices.parameter_names import (
    is_valid_name, mnemonic, names_of, number_of, ros_name)
from drive_bridge.devices.parameters import (
    FC_CONVERSION_FACTORS, ParameterSpec, VLT_CONVERSION_FACTORS)
from drive_bridge.devices.remote_parameters import (
    DOUBLE_KIND, INTEGER_KIND, remote_parameters, TEXT_KIND, typed_value, write_refusal)
from drive_bridge.ros.node.device_parameters.cache import ValueCache
import pytest


def test_names_carry_the_manuals_number_and_a_mnemonic():
    fc = fc51_parameters.FC51_PARAMETERS
    assert ros_name(fc[341]) == 'p3_41_ramp_1_ramp_up_time'
    assert ros_name(fc[412]) == 'p4_12_motor_speed_low_limit_hz'
    assert ros_name(fc[1614]) == 'p16_14_motor_current'
    assert ros_name(fc[3]) == 'p0_03_regional_settings'
    vlt = vlt_parameters.VLT_PARAMETERS['vlt6000']
    assert ros_name(vlt[104]) == 'p104_motor_frequency'
    assert ros_name(vlt[201]) == 'p201_output_frequency_low_limit'  # parentheses left out
    mcd = mcd_parameters.MCD_PARAMETERS
    assert ros_name(mcd['mcd500']['1-4'].spec()) == 'p1_4_current_limit'
    assert ros_name(mcd['mcd3000']['20'].spec()) == 'p20_local_remote_control'  # all in ()


def test_mnemonic_drops_accents_and_cuts_long_names_at_a_word():
    assert mnemonic('Français') == 'francais'
    assert mnemonic('Reference %') == 'reference'
    long = mnemonic('word ' * 20)
    assert len(long) <= 48 and not long.endswith('_') and long.endswith('word')


@pytest.mark.parametrize('table', [
    fc51_parameters.FC51_PARAMETERS, vlt_parameters.VLT_PARAMETERS['vlt5000'],
    vlt_parameters.VLT_PARAMETERS['vlt6000'],
    {entry.serial_number: entry.spec() for entry in mcd_parameters.MCD500 + mcd_parameters.MCD3000
     if entry.serial_number}])
def test_every_tabled_name_is_valid_for_rcl_and_unique(table):
    names = names_of(table.values())
    assert len(names) == len(table)
    assert all(is_valid_name(name) for name in names)
    for name, number in names.items():
        assert number_of(name, names) == number
    assert number_of('p99_nothing', names) is None


def test_rcl_name_rule():
    assert is_valid_name('p3_41_ramp') and is_valid_name('_x.y1')
    assert not is_valid_name('3_41') and not is_valid_name('p3.41') \
        and not is_valid_name('p3-41')


def test_names_that_collide_are_refused():
    specs = [ParameterSpec(1, 'Same', 'uint8'), ParameterSpec(1, 'Same', 'uint8', label='1')]
    with pytest.raises(ValueError, match='names parameter 1 too'):
        names_of(specs)


def _remote(table, factors):
    return {parameter.name: parameter for parameter in remote_parameters(table, factors)}


def test_types_ranges_and_read_only_from_the_table():
    fc = _remote(fc51_parameters.FC51_PARAMETERS, FC_CONVERSION_FACTORS)
    ramp = fc['p3_41_ramp_1_ramp_up_time']
    assert (ramp.kind, ramp.minimum, ramp.maximum, ramp.read_only) == \
        (DOUBLE_KIND, 0.05, 3600.0, '')
    frequency = fc['p1_23_motor_frequency']
    assert (frequency.kind, frequency.minimum, frequency.maximum) == (INTEGER_KIND, 20, 400)
    quick_stop = fc['p3_81_quick_stop_ramp_time']  # manual 004: ramp times 0.05-3600 s
    assert (quick_stop.kind, quick_stop.minimum, quick_stop.maximum) == (DOUBLE_KIND, 0.05, 3600.0)
    current = fc['p16_14_motor_current']  # no limits: the data type's (int32), converted
    assert current.minimum == pytest.approx(-0x80000000 * 0.01) and \
        current.maximum == pytest.approx(0x7FFFFFFF * 0.01)
    assert 'readout' in fc['p16_14_motor_current'].read_only
    assert 'serial-line' in fc['p8_32_baud_rate'].read_only
    assert fc['p15_40_fc_type'].kind == TEXT_KIND
    assert 'p3_10_preset_reference' not in fc  # an array parameter
    assert 'options: 0 = Off, 2 = Enable AMT' in fc['p1_29_automatic_motor_tuning'].constraints()
    assert 'Ramp 1 Ramp-up Time [s]: par. 3-41' in ramp.description()
    vlt = _remote(vlt_parameters.VLT_PARAMETERS['vlt5000'], VLT_CONVERSION_FACTORS)
    assert vlt['p104_motor_frequency'].kind == INTEGER_KIND


def test_mcd_registers_known_only_by_number_are_left_out():
    table = {number: ParameterSpec(number, f'parameter {number}', 'uint16', setting=True)
             for number in range(1, 8)}
    table[4] = mcd_parameters.MCD_PARAMETERS['mcd500']['1-4'].spec()
    remote = _remote(table, parameter_info.RAW_FACTORS)
    assert list(remote) == ['p1_4_current_limit']
    assert remote['p1_4_current_limit'].kind == INTEGER_KIND


def test_values_that_could_run_a_motor_are_refused():
    fc = fc51_parameters.FC51_PARAMETERS
    assert 'maximum speed' in write_refusal('fc', fc[804], 4)
    assert 'jog speed' in write_refusal('fc', fc[804], 3)
    assert 'energises the motor' in write_refusal('fc', fc[129], 2)
    assert write_refusal('fc', fc[804], 2) == '' and write_refusal('fc', fc[129], 0) == ''
    assert write_refusal('vlt', fc[804], 4) == ''  # another family's number


def test_typed_value_converts_what_ros_param_set_sends():
    fc = _remote(fc51_parameters.FC51_PARAMETERS, FC_CONVERSION_FACTORS)
    ramp, frequency, text = (fc['p3_41_ramp_1_ramp_up_time'], fc['p1_23_motor_frequency'],
                             fc['p15_40_fc_type'])
    assert typed_value(ramp, 7) == (7.0, '')
    assert typed_value(frequency, 60.0) == (60, '')
    assert 'whole number' in typed_value(frequency, 60.5)[1]
    assert 'takes a number' in typed_value(frequency, True)[1]
    assert 'takes a number' in typed_value(frequency, 'sixty')[1]
    assert typed_value(text, 'x') == ('x', '') and 'is text' in typed_value(text, 1)[1]


def test_cache_keeps_values_their_age_and_read_refusals():
    now = [10.0]
    cache = ValueCache(clock=lambda: now[0])
    assert cache.store(341, 3.0) is None
    now[0] = 12.5
    assert cache.value(341) == 3.0 and cache.age_s(341) == 2.5
    assert cache.store(341, 4.0) == 3.0
    cache.refused(341, 'rejected by conv: no such parameter')
    assert cache.value(341) is None and cache.error(341).startswith('rejected')
    cache.store(341, 5.0)
    assert cache.error(341) == ''
    cache.forget()
    assert cache.value(341) is None and cache.age_s(341) is None and len(cache) == 0
