"""The README's configuration reference lists every setting the code declares."""

import pathlib
import re

from drive_bridge.config import all_device_settings, BUS_SETTINGS
from drive_bridge.devices.registry import FAMILIES
from drive_bridge.transport.protocols import PROTOCOLS

README = pathlib.Path(__file__).resolve().parents[2] / 'README.md'
NODE_SETTINGS = ('autostart', 'allow_runtime_control_enable')


def _section(title: str) -> str:
    text = README.read_text(encoding='utf-8')
    start = text.index(f'\n## {title}\n')
    end = text.find('\n## ', start + 1)
    return text[start:end if end > 0 else len(text)]


def _table_rows(section: str) -> set:
    """Return every name written as code in the first cell of a table row."""
    names = set()
    for line in section.splitlines():
        if line.startswith('| `'):
            names.update(re.findall(r'`([a-z_]+)`', line.split('|')[1]))
    return names


def test_every_setting_has_a_row_in_the_configuration_reference():
    rows = _table_rows(_section('Configuration reference'))
    declared = {setting.name for setting in BUS_SETTINGS} | set(all_device_settings()) | \
        set(NODE_SETTINGS)
    missing = sorted(declared - rows)
    assert not missing, f'settings missing from the README: {missing}'
    stale = sorted(rows - declared)
    assert not stale, f'README rows that are no setting: {stale}'


def test_every_protocol_and_family_is_named_in_the_configuration_reference():
    section = _section('Configuration reference')
    for name in list(PROTOCOLS) + list(FAMILIES):
        assert f'`{name}`' in section, name
