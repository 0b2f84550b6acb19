"""Unit tests of identification (devices/): what answers at an address, over a fake probe line."""

from drive_bridge.devices import fc51
from drive_bridge.devices import identification as found
from drive_bridge.devices.fc_profile_drive import FcProfileModbusDrive
from drive_bridge.errors import LinkDown
import pytest
from sim_seams import sim_wire, SimProbeLine


def identify(model, protocol='modbus_rtu', families=None, **settings):
    line = SimProbeLine(sim_wire(model, **settings), protocol, families)
    return found.identify(line), line


def reads_only(line):
    return line.wire.sent and not any(request.writes for request in line.wire.sent)


@pytest.mark.parametrize('protocol, families', [
    ('modbus_rtu', ('fc', 'mcd')), ('modbus_tcp', ('fc', 'mcd')), ('fc_protocol', ('fc',)),
    ('ap_ascii', ('mcd',))])
def test_the_families_asked_are_those_of_the_protocol_fc_first(protocol, families):
    assert found.families_asked(protocol) == families


def test_an_fc51_tells_its_model_and_software_version_from_its_type_text():
    answer, line = identify('fc51', software_version='4.12')
    assert answer == found.Answer('fc', 'fc fc51, state ready', 'fc51', '4.12')
    assert line.probed == ['fc'] and reads_only(line)


@pytest.mark.parametrize('model', ['mcd500', 'mcd202'])
def test_an_mcd_starter_is_asked_after_the_fc_question_fails(model):
    answer, line = identify(model)
    assert (answer.family, answer.model, answer.words) == ('mcd', model,
                                                           f'mcd {model}, state ready')
    assert answer.software_version == ''
    assert line.probed == ['fc', 'mcd'] and reads_only(line)


@pytest.mark.parametrize('model', ['vlt5000', 'vlt6000'])
def test_a_vlt_option_card_is_found_by_its_own_codes_without_telling_the_model(model):
    answer, line = identify(model)
    assert answer == found.Answer(
        'vlt', 'vlt (VLT 5000/6000 option card: set model vlt5000 or vlt6000), state ready')
    assert line.probed == ['fc', 'mcd', 'vlt'] and reads_only(line)


def test_silence_at_the_first_question_ends_the_address():
    answer, line = identify(None)
    assert answer is None and line.probed == ['fc'] and len(line.wire.sent) == 1


def test_a_family_that_cannot_sit_at_the_address_is_not_asked():
    answer, line = identify('mcd500', families=('mcd',))
    assert answer.family == 'mcd' and line.probed == ['mcd']


def test_the_option_card_is_not_asked_on_a_protocol_without_coils():
    answer, line = identify('vlt6000', protocol='fc_protocol', families=('vlt',))
    assert answer == found.Answer(None, 'something answers, but not as any supported family')
    assert line.wire.sent == []


def test_a_port_that_is_gone_is_raised_not_taken_for_another_family():
    line = SimProbeLine(sim_wire('fc51'))
    line.wire.link_down = True
    with pytest.raises(LinkDown):
        found.identify(line)
    assert line.probed == ['fc']


def test_a_drive_that_does_not_tell_its_fc_type_is_named_as_a_possible_vlt():
    answer, _ = identify('fc51', type_text='VLT 6000 HVAC')
    assert answer == found.Answer(
        'vlt', "a drive that does not tell its FC type (par. 15-40 reads 'VLT 6000 HVAC'): a "
        'VLT 5000/6000? set family vlt with model vlt5000 or vlt6000, state ready')


def test_unknown_drive_type_says_when_the_type_is_not_readable():
    profile = FcProfileModbusDrive(fc51.DATA, 'auto')
    profile.identity['drive_type'] = 'not readable (exception code 02)'
    assert '(par. 15-40 not readable)' in found.unknown_drive_type(profile, 'ready')
    profile.identity['drive_type'] = 'FC-051PK75T4E20H3BXCXXXSXXXX'
    assert found.unknown_drive_type(profile, 'ready') == ''
    profile.identity['software_version'] = 'not readable (exception code 02)'
    assert found.software_version(profile) == ''
