"""
``drive-bridge backup`` and ``restore``: every parameter of a device to and from a YAML file.

``backup`` reads every parameter twice and saves them if nothing changed in between.
``restore`` checks the whole file before it writes anything, writes in the file's order,
reads every value back, and says which parameters were written when it fails part-way.
The file itself (its format and checks) is :mod:`drive_bridge.tools.backup_file`.
"""

import os
from typing import Any, Dict, List, Optional, Tuple

from drive_bridge.devices import parameter_info as info
from drive_bridge.devices.contracts import DeviceProfile, ParameterOptions
from drive_bridge.devices.parameters import ParameterSpec
from drive_bridge.errors import CommandRefused, DriveBridgeError
from drive_bridge.tools import backup_file
from drive_bridge.tools.cli_session import (
    allow_writes, Interrupted, Progress, run_session, Session, warn, with_session)
from drive_bridge.tools.cli_target import (
    CliError, EXIT_OK, EXIT_USAGE, make_bus, restore_command)


MAX_REASONS_SHOWN = 20
EVERY_ENTRY = 'every entry: '  # a refusal of the whole file for one reason


def backup_rows(session: Session) -> List[Tuple[int, Optional[ParameterSpec]]]:
    """Return (PNU, spec) of each parameter a backup covers, in order."""
    numbers = session.parameters.setting_numbers()
    if not numbers:
        raise CliError(f'{session.name} ({session.device.family} {session.profile.model}) has '
                       'no parameters to back up', EXIT_USAGE)
    table = session.parameters.table()
    return [(number, table.get(number)) for number in numbers]


def read_all(session: Session, numbers: List[int], label: str, args, out) -> Dict[int, Any]:
    """Read each parameter in ``numbers`` (progress on a terminal)."""
    values = {}
    with Progress(len(numbers), label, args, out) as progress:
        for number in numbers:
            values[number] = session.parameters.read(number)
            progress.step()
    return values


def check_backup_file(path: str, force: bool) -> None:
    """Refuse a backup file that cannot be written, or exists (unless ``force``): read nothing."""
    if os.path.isdir(path):
        raise CliError(f'{path} is a directory: give the backup a file name', EXIT_USAGE)
    if os.path.lexists(path) and not force:
        raise CliError(f'{path} exists: nothing read; choose a new file name, or give --force '
                       'to overwrite it', EXIT_USAGE)
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise CliError(f'cannot write {path}: folder {folder} does not exist', EXIT_USAGE)
    if not os.access(folder, os.W_OK):
        raise CliError(f'cannot write {path}: no permission to write in {folder}', EXIT_USAGE)


def command_backup(args, out) -> int:
    """Read every parameter of a device into a YAML file, read them again to verify."""
    check_backup_file(args.file, args.force)

    def backup(session: Session) -> None:
        parameters = session.parameters
        rows = backup_rows(session)
        numbers = [number for number, _ in rows]
        try:
            values = read_all(session, numbers, 'reading', args, out)
            verify = read_all(session, numbers, 'verifying', args, out)
        except KeyboardInterrupt:
            raise Interrupted(f'interrupted: nothing saved to {args.file}') from None
        changed = [number for number in numbers
                   if not info.same_value(values[number], verify[number])]
        if changed:
            raise CliError(f'{len(changed)} parameters changed while backing up (first: '
                           f'{parameters.label(changed[0])}): run the backup again with the '
                           'device stopped; nothing saved')
        for number, spec in rows:  # a value the table refuses: restore would refuse the file
            reason = spec and backup_file.value_reason(spec, values[number], parameters.factors)
            if reason:
                warn(f'{reason}: the device holds it, but restore will refuse this file '
                     'until it is changed')
        content = backup_file.document(
            session.name, session.device.family, session.profile.model,
            session.device.address,
            [backup_row(session, number, spec, values[number]) for number, spec in rows])
        command = restore_command(args, session.config, session.device, session.profile.model)
        try:
            backup_file.write(args.file, content, command)
        except OSError as error:
            raise CliError(f'cannot write {args.file}: {error.strerror or error}: nothing '
                           'saved') from None
        print(f'{len(rows)} parameters of {session.name} saved to {args.file} and verified',
              file=out)
    with_session(args, backup)
    return EXIT_OK


def backup_row(session: Session, number: int, spec: Optional[ParameterSpec],
               value: Any) -> Dict[str, Any]:
    """Return one parameter's entry of a backup file."""
    return {'number': session.parameters.manual_number(number),
            'pnu': number, 'name': spec.name if spec is not None else f'parameter {number}',
            'unit': spec.unit if spec is not None else '',
            'value': info.display_value(spec, value, session.parameters.factors)}


def command_restore(args, out) -> int:
    """Check a backup file whole, write it, then read every value back to verify."""
    try:
        backup = backup_file.load(args.file)
    except backup_file.BackupError as error:
        raise CliError(str(error), EXIT_USAGE) from None
    config, device, bus = make_bus(args)
    if backup.family != device.family:
        refuse_restore(backup, device.name, backup_file.kind_reasons(backup, device.family, ''))
    identity = backup_file.identity_reasons(backup, device.name, device.address)
    if identity and not args.force:
        raise CliError(f'{args.file}: {"; ".join(identity)}: nothing written; give --force to '
                       f'restore it to {device.name} all the same', EXIT_USAGE)
    if identity:
        warn(f'{"; ".join(identity)}: --force restores it to {device.name} all the same')
    config, device = allow_writes(args, config, device)
    run_session(config, device, bus, lambda session: restore_checked(session, backup, args, out),
                writes=True)
    return EXIT_OK


def refuse_restore(backup, name: str, reasons: List[str], total: int = 0) -> None:
    """Raise the CliError of a backup that may not be restored (nothing written)."""
    if len(reasons) == 1 and not total:
        raise CliError(f'{backup.path}: {reasons[0]}: nothing written to {name}', EXIT_USAGE)
    shown = reasons[:MAX_REASONS_SHOWN]
    more = len(reasons) - len(shown)
    lines = [f'{backup.path}: nothing written to {name}: {len(reasons)} of {total} entries '
             'cannot be restored:'] + [f'  {reason}' for reason in shown]
    if more:
        lines.append(f'  ... and {more} more')
    raise CliError('\n'.join(lines), EXIT_USAGE)


def restore_checked(session: Session, backup, args, out) -> None:
    """Restore ``backup`` to the session's device if every entry fits its model."""
    parameters = session.parameters
    profile = parameters.require()
    model = session.resolve_model()
    reasons = backup_file.kind_reasons(backup, session.device.family, model)
    if reasons:
        refuse_restore(backup, session.name, reasons)
    reasons = backup_file.entry_reasons(backup, parameters.table(), parameters.factors,
                                        parameters.manual_number)
    if reasons:
        refuse_restore(backup, session.name, reasons, len(backup.entries))
    values = {number: info.whole_number(value) for number, value in backup.values().items()}
    line = serial_line_values(parameters.table(), values)
    values = {number: value for number, value in values.items() if number not in line}
    options = ParameterOptions(eeprom=args.eeprom)
    reasons = unwritable(session, profile, backup, values, options)
    if len(reasons) == 1 and reasons[0].startswith(EVERY_ENTRY):
        refuse_restore(backup, session.name, reasons)
    if reasons:
        refuse_restore(backup, session.name, reasons, len(values))
    held = read_all(session, list(line), 'reading the serial line settings', args, out)
    write_all(session, values, options, args, out)
    try:
        verify = read_all(session, list(values), 'verifying', args, out)
    except KeyboardInterrupt:
        raise Interrupted(f'interrupted while verifying: all {len(values)} parameters were '
                          f'written to {session.name}, not all read back') from None
    different = [number for number in values
                 if not info.same_value(values[number], verify[number])]
    if different:
        number = different[0]
        raise CliError(f'verify failed for {len(different)} parameters (first: '
                       f'{parameters.label(number)}: wrote {values[number]!r}, reads '
                       f'{verify[number]!r})')
    for number in line:
        if not info.same_value(line[number], held[number]):
            warn(f'{parameters.label(number)}: the file has {line[number]!r}, {session.name} '
                 f'holds {held[number]!r}: not written, as a setting of the serial line; '
                 'change it at the drive, then the bus settings')
    kept = f'; {len(line)} serial line settings ' \
        f'({", ".join(map(parameters.manual_number, line))}) not written' if line else ''
    print(f'{len(values)} parameters restored to {profile.model} {session.name} and verified'
          f'{kept}', file=out)


def serial_line_values(table: Dict[int, ParameterSpec], values: Dict[int, Any]) \
        -> Dict[int, Any]:
    """
    Return the values of the drive's serial line settings (FC 51 8-30..8-33) in a restore.

    A restore never writes them: a new protocol, address, baud rate or parity takes effect
    on the drive's line and cuts it off the bus (the bridge would then write the rest to
    nobody, or to another drive at that address). They are compared with the drive's instead.
    """
    return {number: value for number, value in values.items()
            if number in table and table[number].serial_line}


def unwritable(session: Session, profile: DeviceProfile, backup: backup_file.Backup,
               values: Dict[int, Any], options: ParameterOptions) -> List[str]:
    """
    Return one line per value whose write the device's profile refuses (none: all fit).

    The writes are built, not sent: what the table's check let through but the profile
    would refuse at its write (after the entries before it were written) is found first.
    A refusal of every entry for one reason (``--eeprom`` on an MCD) is one line.
    """
    positions = {entry.pnu: entry.position for entry in backup.entries}
    refused: Dict[int, str] = {}
    for number, value in values.items():
        try:
            profile.parameter_plan(number, value, options)
        except CommandRefused as error:
            refused[number] = str(error)
    if len(values) > 1 and len(refused) == len(values) and len(set(refused.values())) == 1:
        return [f'{EVERY_ENTRY}{next(iter(refused.values()))}']
    return [f'{session.parameters.manual_number(number)} (entry {positions[number]}): {reason}'
            for number, reason in refused.items()]


def write_all(session: Session, values: Dict[int, Any], options: ParameterOptions, args,
              out) -> None:
    """Write ``values`` in order; a failure or Ctrl-C says which were written."""
    numbers = list(values)
    written = 0
    try:
        with Progress(len(numbers), 'writing', args, out) as progress:
            for number in numbers:
                session.parameters.transfer(number, values[number], options)
                written += 1
                progress.step()
    except KeyboardInterrupt:
        raise Interrupted(f'interrupted: {how_far(session, numbers, written, True)}') from None
    except (CliError, DriveBridgeError) as error:
        raise CliError(f'{error}; {how_far(session, numbers, written)}') from None


def how_far(session: Session, numbers: List[int], written: int,
            interrupted: bool = False) -> str:
    """Return which parameters of a restore were written (they are written in file order)."""
    total = len(numbers)
    if written == 0:
        done = f'none of the {total} parameters was written'
    else:
        done = f'{written} of {total} parameters were written (entries 1-{written}, ' \
               f'{session.parameters.manual_number(numbers[0])} to ' \
               f'{session.parameters.manual_number(numbers[written - 1])})'
    if written < total:
        current = session.parameters.manual_number(numbers[written])
        doubt = ' (its write may or may not have reached the device)' if interrupted else ''
        done += f'; {current}{doubt} and the {total - written - 1} after it were not: ' \
                f'{session.name} now holds a mix, restore the file again'
    return done
