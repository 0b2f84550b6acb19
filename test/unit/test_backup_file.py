"""The backup file of drive-bridge: written, read back, and checked against a model's table."""

from drive_bridge.devices import fc51, mcd, vlt
from drive_bridge.devices import parameter_info as info
from drive_bridge.devices.contracts import ParameterOptions
from drive_bridge.devices.fc_profile_drive import FcProfileModbusDrive
from drive_bridge.devices.parameters import FC_CONVERSION_FACTORS
from drive_bridge.tools import backup_file
import pytest

FC51 = fc51.DATA.table('fc51')


def written(tmp_path, rows, **identity):
    values = {'device': 'feeder', 'family': 'fc', 'model': 'fc51', 'address': 1}
    values.update(identity)
    path = str(tmp_path / 'b.yaml')
    backup_file.write(path, backup_file.document(rows=rows, **values))
    return path


def row(pnu, value, **fields):
    spec = FC51[pnu]
    return dict({'number': spec.label, 'pnu': pnu, 'name': spec.name, 'unit': spec.unit,
                 'value': value}, **fields)


def reasons(backup):
    return backup_file.entry_reasons(backup, FC51, FC_CONVERSION_FACTORS, fc51.parameter_label)


def test_a_written_backup_reads_back_whole(tmp_path):
    path = written(tmp_path, [row(341, 3.0), row(804, 2)], date='2025-06-01T14:03:07+02:00')
    with open(path) as stream:
        assert stream.readline().startswith('# drive-bridge parameter backup of feeder')
    backup = backup_file.load(path)
    assert (backup.device, backup.family, backup.model, backup.address, backup.date) == \
        ('feeder', 'fc', 'fc51', 1, '2025-06-01T14:03:07+02:00')
    assert backup.entries[0] == backup_file.Entry(1, 341, 3.0, '3-41', 'Ramp 1 Ramp-up Time',
                                                  's')
    assert backup.values() == {341: 3.0, 804: 2} and reasons(backup) == []


def test_a_text_value_that_looks_like_a_number_stays_text(tmp_path):
    spec = vlt.DATA.table('vlt6000')[533]
    path = written(tmp_path, [{'number': '533', 'pnu': 533, 'name': spec.name, 'unit': '',
                               'value': '0012'}], family='vlt', model='vlt6000')
    assert backup_file.load(path).values() == {533: '0012'}
    assert backup_file.value_reason(spec, 12, {0: 1.0}) == \
        'Display Text 1 (par. 533) is a text parameter: 12 is not text (quote it in the file)'


@pytest.mark.parametrize('edit, reason', [
    (row(341, 0.01), 'Ramp 1 Ramp-up Time (par. 3-41): 0.01 s is below the minimum 0.05 s'),
    (row(341, 3.0, number='3-42'), 'number 3-42 does not match pnu 341 (3-41)'),
    (row(341, 3.0, unit='min'), "unit 'min' in the file, 's' in the table"),
    (row(1614, 1.0), 'Motor Current is a readout, not a setting'),
    (dict(row(341, 3.0), pnu=5000, number='50-00'), 'pnu 5000 is not a parameter'),
])
def test_each_entry_is_checked(tmp_path, edit, reason):
    found = reasons(backup_file.load(written(tmp_path, [row(804, 2), edit])))
    assert len(found) == 1 and reason in found[0], found


def test_kind_and_identity():
    backup = backup_file.Backup('f', 'fc_1', 'mcd', 'mcd3000', 21, None)
    assert backup_file.kind_reasons(backup, 'mcd', 'mcd500') == [
        'it is a backup of a mcd3000; this device is a mcd500: parameters of one model do not '
        'fit another']
    assert backup_file.kind_reasons(backup, 'mcd', 'mcd3000') == []
    assert backup_file.identity_reasons(backup, 'crusher', 20) == [
        "it is a backup of device 'fc_1', not 'crusher'",
        'it was taken at address 21, crusher is at 20']


def test_parameter_info_of_a_drive_and_a_starter():
    drive = FcProfileModbusDrive(fc51.DATA, 'fc51')
    assert info.label(drive, 1614) == '16-14'
    ramp = info.spec_for(drive, 341, ParameterOptions())
    assert info.format_value(ramp, 425 * 0.01, FC_CONVERSION_FACTORS) == '4.25 s'
    assert info.format_value(ramp, 0.1 * 3, FC_CONVERSION_FACTORS) == '0.3 s'
    custom = info.spec_for(drive, 341, ParameterOptions(data_type='uint16'))
    assert (custom.data_type, custom.conversion, custom.maximum) == ('uint16', -2, None)
    assert info.spec_for(drive, 9998, ParameterOptions()) is None
    starter = mcd.McdProfile('mcd500')
    table = info.parameter_table(starter)
    assert len(table) == 591 and table[4].label == '1-4' and table[4].unit == '% FLC'
    assert table[7].name == 'parameter 7' and table[7].data_type == 'uint16'
    assert info.parse_value(table[4], '350') == 350
    assert info.parse_value(vlt.DATA.table('vlt6000')[533], '1234567890') == '1234567890'
    assert info.same_value(4.25, 425 * 0.01) and not info.same_value(4.25, 4.26)
