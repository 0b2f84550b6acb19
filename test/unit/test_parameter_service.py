"""Unit tests of the parameter service (devices/), over a fake line to a simulated device."""

from drive_bridge.devices import fc51 as fc51_family, vlt
from drive_bridge.devices.contracts import ParameterOptions
from drive_bridge.devices.fc_profile_drive import FcProfileModbusDrive
from drive_bridge.devices.lvsg import LvsgProfile
from drive_bridge.devices.mcd import McdProfile
from drive_bridge.devices.parameter_service import ParameterService, parse_parameter_number
from drive_bridge.errors import CommandRefused, MonitorOnly, ProtocolError, ReadBackMismatch
from drive_bridge.protocol.requests import WriteCoil
import pytest
from sim_seams import sim_wire, SimLine

RAMP_UP = 341  # FC 51 par. 3-41, uint32, conversion -2, 0.05-3600 s


def service(model, profile, writes_allowed=True, name='feeder'):
    wire = sim_wire(model)
    line = SimLine(wire, profile, writes_allowed)
    return ParameterService(name, profile, line), line, wire.device.model


def fc51(writes_allowed=True, model='fc51'):
    return service('fc51', FcProfileModbusDrive(fc51_family.DATA, model), writes_allowed)


def writes(line):
    return [request for request in line.sent if request.writes]


# -- what is known, without a transaction ------------------------------------------------
def test_the_table_lists_the_models_parameters_with_the_manuals_numbers():
    parameters, line, _ = fc51()
    table = parameters.table()
    assert table[RAMP_UP].label == '3-41' and table[RAMP_UP].unit == 's'
    assert parameters.label(RAMP_UP) == '3-41' and parameters.manual_number(RAMP_UP) == '3-41'
    assert parameters.factors[-2] == 0.01
    assert parameters.setting_numbers() == sorted(
        number for number, spec in table.items() if spec.setting)
    assert line.sent == []


@pytest.mark.parametrize('text, number', [('3-41', 341), ('16-14', 1614), ('205', 205)])
def test_a_drive_parameter_is_numbered_as_the_manual_writes_it(text, number):
    assert fc51()[0].number(text) == number
    assert parse_parameter_number(text) == number


@pytest.mark.parametrize('text', ['3-4', '3-4x', 'x', '3-041', '3-٤١'])
def test_a_number_not_written_as_in_the_manual_is_refused_in_words(text):
    with pytest.raises(CommandRefused, match=f'parameter number {text!r}: write it as in the '
                       'manual, e.g. 3-41, 16-14 or 205'):
        fc51()[0].number(text)


def test_an_mcd_parameter_is_found_by_its_designation_or_its_modbus_number():
    parameters, line, _ = service('mcd500', McdProfile('mcd500'), name='crusher')
    assert parameters.number('1-4') == 4 and parameters.number('4') == 4
    assert parameters.manual_number(4) == '1-4' and parameters.label(4) == '4'
    with pytest.raises(CommandRefused, match='parameter 99-1: not in the table of the mcd500; '
                       'give the Modbus Module.s parameter number'):
        parameters.number('99-1')
    assert line.sent == []


def test_a_profile_without_parameter_access_is_refused_before_anything_is_sent():
    profile = LvsgProfile('mcd202', input_register=0, output_register=100)
    parameters = ParameterService('gate', profile, SimLine(sim_wire(None), profile))
    for access in (lambda: parameters.read(1), lambda: parameters.write(1, 2),
                   lambda: parameters.spec(1), parameters.setting_numbers):
        with pytest.raises(CommandRefused, match=r'^gate \(lvsg\) has no parameter access$'):
            access()
    assert parameters.line.sent == []


def test_model_auto_is_learned_from_the_device_before_the_table_is_built():
    parameters, line, _ = fc51(model='auto')
    assert parameters.table()[RAMP_UP].label == '3-41'
    assert line.calls == ['resolve_model', 'poll'] and parameters.profile.model == 'fc51'
    parameters.table()
    assert line.calls.count('poll') == 1


# -- read and write ------------------------------------------------------------------------
def test_a_read_returns_the_devices_value_in_display_units():
    parameters, line, device = fc51()
    device.parameters[RAMP_UP] = 425
    assert parameters.read(RAMP_UP) == pytest.approx(4.25)
    assert writes(line) == []


def test_a_write_goes_to_ram_is_read_back_and_asks_the_line_first():
    parameters, line, device = fc51()
    assert parameters.write(RAMP_UP, 7.5) == pytest.approx(7.5)
    assert device.parameters[RAMP_UP] == 750
    assert writes(line)[0] == WriteCoil(fc51_family.DATA.eeprom_coil, False)  # RAM only
    assert line.calls.index('check_before_writing') < line.calls.index('run')
    assert not line.sent[-1].writes  # the read-back comes last


def test_eeprom_on_request_sets_the_store_coil_before_the_write():
    parameters, line, device = fc51()
    parameters.write(RAMP_UP, 9.0, ParameterOptions(eeprom=True))
    assert writes(line)[0] == WriteCoil(fc51_family.DATA.eeprom_coil, True)
    assert device.parameters[RAMP_UP] == 900


@pytest.mark.parametrize('value, reason', [
    (0.01, r'Ramp 1 Ramp-up Time \(par. 3-41\): 0.01 s is below the minimum 0.05 s: nothing '
           'written'),
    ('fast', r"^Ramp 1 Ramp-up Time \(par. 3-41\) takes a number, not 'fast': nothing written$"),
])
def test_a_value_the_table_refuses_sends_nothing(value, reason):
    parameters, line, device = fc51()
    before = dict(device.parameters)
    with pytest.raises(CommandRefused, match=reason):
        parameters.write(RAMP_UP, value)
    assert line.sent == [] and 'check_before_writing' not in line.calls
    assert device.parameters == before


def test_a_monitor_only_device_gets_no_write_and_nothing_of_its_plan():
    parameters, line, device = fc51(writes_allowed=False)
    before = dict(device.parameters)
    with pytest.raises(MonitorOnly, match=r'^feeder is monitor only \(allow_control: false\): '
                       r'write Ramp 1 Ramp-up Time \(par. 3-41\) = 7.5 not sent$'):
        parameters.write(RAMP_UP, 7.5)
    with pytest.raises(MonitorOnly):
        parameters.transfer(RAMP_UP, 7.5)
    assert line.sent == [] and device.parameters == before
    assert parameters.read(RAMP_UP) == pytest.approx(3.0)  # reads still go


def test_a_vlt_text_read_writes_its_index_so_a_monitor_only_vlt_refuses_it():
    profile = FcProfileModbusDrive(vlt.DATA, 'vlt6000')
    parameters, line, _ = service('vlt6000', profile, writes_allowed=False, name='fan')
    with pytest.raises(MonitorOnly, match=r'^fan is monitor only .*: read Display Text 1 '
                       r'\(par. 533\) not sent$'):
        parameters.read(533)
    assert line.sent == []


def test_a_value_that_reads_back_different_is_reported():
    parameters, line, device = fc51()

    def dropped(requests, doing):  # the device acknowledges the write and keeps its value
        line.calls.append('run')
        return [None if request.writes else line.wire.transact(request)
                for request in requests]
    line.run = dropped
    device.parameters[RAMP_UP] = 300
    with pytest.raises(ReadBackMismatch, match=r'^3-41: wrote 7.5, but it reads back 3.0$'):
        parameters.write(RAMP_UP, 7.5)


def test_a_reply_that_does_not_decode_is_a_protocol_error():
    parameters, line, _ = fc51()
    line.run = lambda requests, doing: []
    with pytest.raises(ProtocolError, match=r'^feeder: read Ramp 1 Ramp-up Time \(par. 3-41\): '
                       'the reply does not decode: '):
        parameters.read(RAMP_UP)


def test_an_mcd_register_is_read_and_written_raw():
    parameters, line, device = service('mcd500', McdProfile('mcd500'), name='crusher')
    assert parameters.read(4) == device.parameters[4]
    assert parameters.write(4, 7) == 7 and device.parameters[4] == 7
    with pytest.raises(CommandRefused, match='EEPROM|eeprom'):
        parameters.write(4, 8, ParameterOptions(eeprom=True))
    assert device.parameters[4] == 7
