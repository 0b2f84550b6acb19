"""
The parameter backup file of ``drive-bridge backup`` and ``restore``: write, read, check.

A backup names the device (name, family, model, address), the date (ISO 8601) and, for each
parameter, its number as the manual writes it (``3-41``; MCD ``1-4`` or the module's
``4``), its PNU (the number on the bus, the key a restore goes by), name, unit and value in
display units::

    format: 2
    device: feeder
    family: fc
    model: fc51
    address: 1
    date: '2025-06-01T14:03:07+02:00'
    parameters:
    - number: 3-41
      pnu: 341
      name: Ramp 1 Ramp-up Time
      unit: s
      value: 3.0

Reading refuses a key given twice, a PNU that is not an integer (YAML reads ``True:`` as a
boolean) and unknown keys, each in one line. The older form (``parameters:`` mapping PNU
to value) is still read. :func:`entry_reasons` checks every entry against the device's
parameter table before a restore writes anything.
"""

from dataclasses import dataclass, field
import datetime
import os
import tempfile
from typing import Any, Dict, List, Mapping, Optional

from drive_bridge.config.params_file import load_yaml_file
from drive_bridge.devices.parameters import check_value, ParameterSpec, TEXT
from drive_bridge.errors import ConfigError

FORMAT = 2
TOP_KEYS = ('format', 'device', 'family', 'model', 'address', 'date', 'parameters')
ENTRY_KEYS = ('number', 'pnu', 'name', 'unit', 'value')


class BackupError(Exception):
    """A backup file that cannot be restored, in one line."""


@dataclass(frozen=True)
class Entry:
    """One parameter of a backup; ``label``, ``name`` and ``unit`` are None in old files."""

    position: int  # 1-based, in the file's order
    pnu: int
    value: Any
    label: Optional[str] = None
    name: Optional[str] = None
    unit: Optional[str] = None


@dataclass
class Backup:
    """A backup file as read (not yet checked against a device)."""

    path: str
    device: Optional[str]
    family: Optional[str]
    model: Optional[str]
    address: Optional[int]
    date: Optional[str]
    entries: List[Entry] = field(default_factory=list)

    def values(self) -> Dict[int, Any]:
        """Return PNU -> value in the file's order."""
        return {entry.pnu: entry.value for entry in self.entries}


# -- writing --------------------------------------------------------------------------------
def now_iso8601() -> str:
    """Return the local time with its UTC offset, to the second (ISO 8601)."""
    return datetime.datetime.now().astimezone().isoformat(timespec='seconds')


def document(device: str, family: str, model: str, address: int,
             rows: List[Dict[str, Any]], date: Optional[str] = None) -> Dict[str, Any]:
    """Return the document of a backup; ``rows`` hold number, pnu, name, unit and value."""
    return {'format': FORMAT, 'device': device, 'family': family, 'model': model,
            'address': address, 'date': date or now_iso8601(),
            'parameters': [{key: row[key] for key in ENTRY_KEYS} for row in rows]}


def write(path: str, content: Dict[str, Any], restore_command: str = '') -> None:
    """
    Write a backup document as YAML (keys in the order above), under a header comment.

    The header names the device and gives the whole command that restores the file
    (``restore_command``). The file is written beside ``path`` and then renamed onto it, so
    a failure part-way leaves no half file (and an older file under that name as it was).
    """
    import yaml
    command = restore_command or 'drive-bridge restore ... FILE'
    header = (f'# drive-bridge parameter backup of {content["device"]} ({content["family"]} '
              f'{content["model"]} at address {content["address"]}). Restore it with:\n'
              f'#   {command}\n')
    folder, name = os.path.split(os.path.abspath(path))
    handle, temporary = tempfile.mkstemp(prefix=f'.{name}.', dir=folder)
    try:
        with os.fdopen(handle, 'w') as stream:
            stream.write(header)
            yaml.safe_dump(content, stream, sort_keys=False, allow_unicode=True)
        os.chmod(temporary, 0o666 & ~_umask())
        os.replace(temporary, path)
    except BaseException:
        os.unlink(temporary)
        raise


def _umask() -> int:
    """Return the process's umask (the mode a plain open would give a new file)."""
    mask = os.umask(0)
    os.umask(mask)
    return mask


# -- reading --------------------------------------------------------------------------------
def load(path: str) -> Backup:
    """Return the backup in ``path``; raise BackupError in one line if it is not one."""
    try:
        content = load_yaml_file(path, str(path))
    except ConfigError as error:
        raise BackupError(str(error)) from None
    if not isinstance(content, dict) or 'parameters' not in content:
        raise BackupError(f'{path} is not a drive-bridge backup (it has no parameters)')
    unknown = [str(key) for key in content if key not in TOP_KEYS]
    if unknown:
        raise BackupError(f'{path}: unknown keys {", ".join(unknown)} (a backup has '
                          f'{", ".join(TOP_KEYS)})')
    if content.get('format', 1) not in (1, FORMAT):
        raise BackupError(f'{path}: backup format {content["format"]!r} is not one this '
                          f'drive-bridge reads (1 or {FORMAT})')
    address = content.get('address')
    if address is not None and type(address) is not int:
        raise BackupError(f'{path}: address {address!r} is not a whole number')
    date = content.get('date')
    return Backup(path, _text_or_none(content.get('device')),
                  _text_or_none(content.get('family')), _text_or_none(content.get('model')),
                  address, None if date is None else str(date),
                  _entries(path, content['parameters']))


def _text_or_none(value: Any) -> Optional[str]:
    return None if value is None else str(value)


def _entries(path: str, parameters: Any) -> List[Entry]:
    if isinstance(parameters, dict):  # format 1: PNU -> value
        entries = []
        for position, (pnu, value) in enumerate(parameters.items(), 1):
            _check_pnu(path, pnu, f'key {pnu!r}')
            entries.append(Entry(position, pnu, value))
        return entries
    if not isinstance(parameters, list) or not parameters:
        raise BackupError(f'{path}: parameters must be a list of entries (number, pnu, name, '
                          'unit, value)')
    return [_entry(path, position, row) for position, row in enumerate(parameters, 1)]


def _entry(path: str, position: int, row: Any) -> Entry:
    where = f'{path}: parameter entry {position}'
    if not isinstance(row, dict):
        raise BackupError(f'{where} is not a mapping of number, pnu, name, unit and value')
    unknown = [str(key) for key in row if key not in ENTRY_KEYS]
    if unknown:
        raise BackupError(f'{where}: unknown keys {", ".join(unknown)} (an entry has '
                          f'{", ".join(ENTRY_KEYS)})')
    for key in ('pnu', 'value'):
        if key not in row:
            raise BackupError(f'{where} has no {key}')
    _check_pnu(path, row['pnu'], f'entry {position}: pnu {row["pnu"]!r}')
    return Entry(position, row['pnu'], row['value'],
                 *(_text_or_none(row.get(key)) for key in ('number', 'name', 'unit')))


def _check_pnu(path: str, pnu: Any, what: str) -> None:
    if type(pnu) is not int:  # bool is an int to Python: True would be parameter 1
        kind = 'a boolean to YAML' if isinstance(pnu, bool) else type(pnu).__name__
        raise BackupError(f'{path}: {what} is not a parameter number ({kind}); write the '
                          'PNU as a whole number, e.g. 341')


# -- checks against the device --------------------------------------------------------------
def identity_reasons(backup: Backup, name: str, address: int) -> List[str]:
    """Return why the backup is of another device (name or address), or nothing."""
    reasons = []
    if backup.device is not None and backup.device != name:
        reasons.append(f'it is a backup of device {backup.device!r}, not {name!r}')
    if backup.address is not None and backup.address != address:
        reasons.append(f'it was taken at address {backup.address}, {name} is at {address}')
    return reasons


def kind_reasons(backup: Backup, family: str, model: str) -> List[str]:
    """Return why the backup does not fit this family and model, or nothing (no override)."""
    if backup.family != family:
        return [f'it is a backup of a {backup.family or "unnamed family"} device; this '
                f'device is {family}']
    if backup.model != model:
        return [f'it is a backup of a {backup.model or "device of no stated model"}; this '
                f'device is a {model}: parameters of one model do not fit another']
    return []


def entry_reasons(backup: Backup, table: Mapping[int, ParameterSpec],
                  factors: Mapping[int, float], label_of) -> List[str]:
    """
    Return one line per entry that may not be written, or nothing when all may.

    Each PNU once, known to ``table`` and a setting there; the number as written matching
    the PNU (``label_of(pnu)``); the unit, where the file gives one, the table's; the value
    within the entry's type, limits and options (:func:`check_value`).
    """
    reasons = []
    seen: Dict[int, int] = {}
    for entry in backup.entries:
        label = label_of(entry.pnu)
        where = f'{label} (entry {entry.position})'
        spec = table.get(entry.pnu)
        if entry.pnu in seen:
            reasons.append(f'{where}: pnu {entry.pnu} is given twice (entries '
                           f'{seen[entry.pnu]} and {entry.position})')
            continue
        seen[entry.pnu] = entry.position
        if entry.label is not None and entry.label != label:
            reasons.append(f'entry {entry.position}: number {entry.label} does not match pnu '
                           f'{entry.pnu} ({label}): correct one of them')
        elif spec is None:
            reasons.append(f"{where}: pnu {entry.pnu} is not a parameter of this model's "
                           'table')
        elif spec.setting is False:
            reasons.append(f'{where}: {spec.name} is a readout, not a setting')
        elif entry.unit is not None and entry.unit != spec.unit:
            reasons.append(f'{where}: unit {entry.unit!r} in the file, {spec.unit!r} in the '
                           'table: the value would mean something else')
        else:
            reason = value_reason(spec, entry.value, factors)
            if reason:
                reasons.append(f'{where}: {reason}')
    return reasons


def value_reason(spec: ParameterSpec, value: Any, factors: Mapping[int, float]) -> str:
    """Return why ``value`` does not fit ``spec`` ('' when it does), with a YAML hint."""
    reason = check_value(spec, value, dict(factors)) or ''
    if reason and spec.data_type == TEXT and not isinstance(value, str):
        reason += ' (quote it in the file)'
    return reason
