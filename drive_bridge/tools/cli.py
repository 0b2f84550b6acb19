"""
``drive-bridge``: commission devices on a bus from a terminal, without ROS.

Subcommands: ``scan`` (find devices in an address range, tell family and model), ``status``
(one device, decoded), ``get``/``set`` (a parameter by its manual number, with conversion
and units), ``backup``/``restore`` (parameters to and from YAML, checked and verified) and
``monitor`` (live status). The bus comes from the node's parameters file (``--config
line.yaml --device conv``) or from options (``--port /dev/ttyUSB0 --family fc --address
1``).

Every transaction goes through the bus's transaction runner, as in the node: a write to a
monitor-only device (``allow_control: false``) is refused unless ``--force`` is given for
that command, a parameter number on process data or control registers is refused by the
profile, and an exception 04 is explained with the drive's register 7. Before a command's
first write the device at the address is identified with reads only, as ``scan`` does:
nothing is written to a device that does not answer as the family and model given (nor to
a silent address). ``restore`` checks the whole file (device, family, model, every number,
type, limit and option) before it writes anything. Progress goes to stderr, and only while
stderr is a terminal. Exit status: 0 done, 1 the bus or device failed, 2 a bad argument
or file, 130 interrupted (Ctrl-C), 141 the reader of stdout went away (``| head``).
"""

import argparse
from dataclasses import replace
import logging
import math
import os
import sys
import textwrap
import time
from typing import Any, Callable, Dict, List, NamedTuple, Optional, Sequence, Tuple

from drive_bridge import config as cfg
from drive_bridge.bus.device import BusDevice
from drive_bridge.bus.runner import retryable, run_poll, TransactionRunner
from drive_bridge.console import drop_stdout, EXIT_BROKEN_PIPE
from drive_bridge.devices import mcd_parameters
from drive_bridge.devices.contracts import DeviceReading, ParameterAccess, ParameterOptions
from drive_bridge.devices.drive import COIL_STATUS, FcProfileDrive, PROCESS_COILS
from drive_bridge.devices.parameters import DATA_TYPES, parameter_address, ParameterSpec, TEXT
from drive_bridge.devices.registry import FAMILIES
from drive_bridge.errors import (
    CommandRefused, ConfigError, DeviceException, DriveBridgeError, LinkDown, ModelMismatch,
    MonitorOnly, NoResponse, ProtocolError, TransportError)
from drive_bridge.protocol.fc_control import StatusWord
from drive_bridge.protocol.requests import ReadCoils, ReadRegisters
from drive_bridge.protocol.words import coils_to_words
from drive_bridge.tools import backup_file, parameter_info as info
from drive_bridge.tools.cli_target import (
    bus_values, CliError, EXIT_FAILED, EXIT_INTERRUPTED, EXIT_OK, EXIT_USAGE,
    file_block, make_bus, restore_command)
from drive_bridge.transport.protocols import PROTOCOLS

SCAN_FAMILIES = ('fc', 'mcd')  # asked in this order; then the VLT option card (see scan)
# The families identify() can tell: checked before a write. Not lvsg: behind its gateway
# the starter's process image answers as no family the reads know.
IDENTIFIED_FAMILIES = SCAN_FAMILIES + ('vlt',)
# Exception codes only the VLT option card answers (its drive's FC-protocol error codes and
# its own 64-67, 255); a Modbus device answers 01-0B.
OPTION_CARD_CODES = frozenset({0, 17, 64, 65, 66, 67, 130, 131, 255})
VLT_COMMON_PARAMETER = 538  # the alarm word: both VLT 5000 and VLT 6000 have it
MAX_REASONS_SHOWN = 20
PARAMETER_TYPES = sorted(DATA_TYPES) + [TEXT]


class Interrupted(CliError):
    """Ctrl-C, with what was done by then."""

    def __init__(self, text: str = 'interrupted'):
        super().__init__(text, EXIT_INTERRUPTED)


def warn(text: str) -> None:
    """Print a warning line on stderr."""
    print(f'drive-bridge: WARNING: {text}', file=sys.stderr, flush=True)


# -- the bus and the device ----------------------------------------------------------------
def allow_writes(args: argparse.Namespace, config, device):
    """
    Return (config, device) for a command that writes: refuse a monitor-only device.

    With ``--force`` the device's ``allow_control`` is overridden for this command only,
    and a warning line naming it goes to stderr.
    """
    if device.allow_control:
        return config, device
    if not args.force:
        raise CliError(f'{device.name} is monitor only (allow_control: false): nothing '
                       'written; give --force to write to it for this command only', EXIT_USAGE)
    warn(f'{device.name} is configured allow_control: false (monitor only); --force writes '
         'to it for this command only')
    device = replace(device, allow_control=True)
    return replace(config, devices=[device]), device


class Session:
    """
    One device on an open bus; transactions run here, in this thread.

    They go through the bus's transaction runner, so the same checks hold as in the node:
    a monitor-only device (``allow_control: false``) gets no write at all, and a refusal is
    explained as the node explains it (exception 04: register 7 read for the detail).
    """

    def __init__(self, config, device, runner: Optional[TransactionRunner] = None,
                 bus: Optional[Dict[str, Any]] = None):
        self.config = config
        self.device = device
        self.record = BusDevice(device.make_spec(), time.monotonic())
        self.profile = self.record.profile
        self._owns_port = runner is None  # else a port another session opened (scan)
        self.runner = runner or open_runner(config)
        # The bus settings to ask what answers at the address when the device does not
        # answer as its family does, and before the first write (None: a probe of scan,
        # which asks that itself and never writes).
        self.bus = bus
        self._answer: Optional[Answer] = None
        self._asked = self._checked = False
        self._polled = False
        self._table: Optional[Dict[int, ParameterSpec]] = None

    @property
    def name(self) -> str:
        """Return the device's name."""
        return self.device.name

    def close(self) -> None:
        """Close the port, if this session opened it."""
        if self._owns_port:
            self.runner.transport.close()

    def run(self, requests: Sequence[object], doing: str = '') -> list:
        """Run requests in order; a refusal is a CliError in the device's words."""
        results = []
        for request in requests:
            try:
                results.append(self._transact(request))
            except DeviceException as error:
                self.check_family()
                what = f' {doing}' if doing else ' it'
                raise CliError(f'{self.name} refused{what}: '
                               f'{self.runner.explain(self.record, error)}') from None
            except NoResponse:
                if not doing:
                    raise
                raise self.silent(doing) from None
            except TransportError as error:
                if not doing or isinstance(error, LinkDown):
                    raise
                raise CliError(f'{self.name}: {doing}: {error}') from None
        return results

    def _transact(self, request) -> Any:
        """Run one request; a read is repeated after a lost or garbled reply, as the node does."""
        attempt = 0
        while True:
            try:
                return self.runner.transact(self.record, request)
            except TransportError as error:
                if request.writes or not retryable(error) or \
                        attempt >= self.config.timing.retries:
                    raise
                attempt += 1

    def poll(self) -> DeviceReading:
        """Read the device once and return its decoded reading."""
        try:
            reading = run_poll(self.runner, self.record, self.config.timing.retries)
        except DeviceException as error:
            self.check_family()
            raise CliError(f'{self.name} refused the poll: '
                           f'{self.runner.explain(self.record, error)}') from None
        except (ModelMismatch, ProtocolError):
            self.check_family()
            raise
        self._polled = True
        return reading

    def silent(self, doing: str = '') -> CliError:
        """Return the CliError of a device that did not answer, naming its address."""
        link = self.config.link
        what = f' to {doing}' if doing else ''
        return CliError(f'{self.name}: no reply from address {self.device.address}{what} '
                        f'within {link.timeout_s:g} s ({link.protocol}, {link.describe()}): '
                        'is a device at that address, on this line, with this protocol, baud '
                        'rate and parity?')

    def answer(self) -> Optional['Answer']:
        """Return what answers at the device's address (asked once, reads only: identify)."""
        if not self._asked:
            self._answer = identify(self.bus, self.device.address, self.runner,
                                    self.config.timing.retries)
            self._asked = True
        return self._answer

    def check_family(self) -> None:
        """
        Raise a CliError if what answers at the address is not of the device's family.

        Asked (reads only, as ``scan`` asks) when the device refuses or garbles what its
        family is asked: ``--family mcd`` at an FC 51's address says so, instead of an MCD
        200's register limits.
        """
        if self.bus is None:
            return
        found = self.answer()
        if found is None or found.family in (None, self.device.family):
            return
        raise CliError(other_family(self, found), EXIT_USAGE)

    def check_before_writing(self) -> None:
        """
        Raise a CliError unless the device at the address answers as its family and model.

        Asked once, before the session's first write, with reads only (:func:`identify`, as
        ``scan`` asks): a write meant for one register map never lands in another device's.
        Families the reads cannot identify (lvsg) are not asked; a model the reads cannot
        tell (VLT 5000 or 6000) is taken as given.
        """
        if self._checked or self.bus is None or \
                self.device.family not in IDENTIFIED_FAMILIES:
            return
        found = self.answer()
        if found is None:
            raise CliError(f'{self.silent("identify it before writing")} Nothing written.')
        if found.family != self.device.family:
            raise CliError(other_family(self, found, '; nothing written'), EXIT_USAGE)
        configured = self.profile.configured_model
        if found.model not in (None, configured) and configured != 'auto':
            try:  # the profile decides what fits its model (an MCD 201 answers as a 202)
                self.poll()
            except ModelMismatch:
                raise CliError(f'{self.name}: address {self.device.address} answers as '
                               f'{found.words}, not as model {configured}: give --model '
                               f'{found.model} (or the right address); nothing written',
                               EXIT_USAGE) from None
        self._checked = True

    def resolve_model(self) -> str:
        """Return the model; with model auto, poll once so that the device tells it."""
        if self.profile.configured_model == 'auto' and not self._polled:
            self.poll()
            self._table = None
        return self.profile.model

    # -- parameters ---------------------------------------------------------------------
    def require_parameters(self) -> ParameterAccess:
        """Return the profile if it has parameter access, else raise CliError."""
        if not isinstance(self.profile, ParameterAccess):
            raise CliError(f'{self.name} ({self.device.family}) has no parameter access',
                           EXIT_USAGE)
        return self.profile

    def table(self) -> Dict[int, ParameterSpec]:
        """Return what is known of each parameter of the device's model."""
        if self._table is None:
            self.resolve_model()
            self._table = info.parameter_table(self.profile)
        return self._table

    @property
    def factors(self) -> Dict[int, float]:
        """Return the conversion factors of the device's family."""
        return info.conversion_factors(self.profile)

    def label(self, number: int) -> str:
        """Return parameter ``number`` as the bus numbers it (FC: 3-41; MCD: 4)."""
        return info.label(self.profile, number)

    def manual_number(self, number: int) -> str:
        """Return parameter ``number`` as its manual writes it (FC: 3-41; MCD 500: 1-4)."""
        spec = self.table().get(number)
        return spec.label if spec is not None and spec.label else self.label(number)

    def number(self, text: str) -> int:
        """Return the PNU of ``text`` as the manual writes it (FC 3-41, VLT 205, MCD 4 or 1-4)."""
        if isinstance(self.profile, FcProfileDrive) or text.isdigit():
            return parse_parameter_number(text)
        model = self.resolve_model()
        entry = mcd_parameters.find(model, text)
        if entry is None or entry.serial_number is None:
            known = 'not in the table' if entry is None else 'without a known register'
            raise CliError(f'parameter {text}: {known} of the {model}; give the Modbus '
                           "Module's parameter number (manual 000 section 6: Parameter N is "
                           'register 40008 + N), e.g. 4 for 1-4', EXIT_USAGE)
        return entry.serial_number

    def spec(self, number: int, options: ParameterOptions) -> Optional[ParameterSpec]:
        """Return how ``number`` is read and written with ``options`` (None: not known)."""
        self.require_parameters()
        return info.spec_for(self.profile, number, options, self.table())

    def typed_spec(self, typed: str, number: int,
                   options: ParameterOptions) -> Optional[ParameterSpec]:
        """
        Return :meth:`spec`; for a drive parameter it does not know, a CliError instead.

        The error says how ``typed`` was read (``3-99``: PNU 399) and which options describe
        a parameter outside the table.
        """
        spec = self.spec(number, options)
        if spec is not None or not isinstance(self.profile, FcProfileDrive):
            return spec
        shown_as = self.label(number)
        read_as = f'(PNU {number})' if shown_as == typed else \
            f'is read as {shown_as} (PNU {number}), which'
        raise CliError(f'parameter {typed} {read_as} is not in the {self.profile.model} table: '
                       f'give its data type with --type ({", ".join(PARAMETER_TYPES)}) and its '
                       'conversion index with --conversion (e.g. -2 for 0.01), as the manual '
                       'lists them', EXIT_USAGE)

    def parameter(self, number: int, value=None, options: ParameterOptions = ParameterOptions()):
        """Read (value None) or write one parameter; return its value or the outcome."""
        profile = self.require_parameters()
        self.resolve_model()  # model auto: the parameter map depends on what the device is
        plan = profile.parameter_plan(number, value, options)
        if any(request.writes for request in plan.transactions):
            if not self.record.owner.writes_allowed:  # as the node: nothing of the plan sent
                raise MonitorOnly(f'{self.name} is monitor only (allow_control: false): '
                                  f'{plan.label} not sent')
            self.check_before_writing()  # e.g. a VLT text parameter's index write (IND)
        results = self.run(plan.transactions, plan.label)
        try:
            return plan.decode(results)
        except (ValueError, IndexError, TypeError) as error:
            raise CliError(f'{self.name}: {plan.label}: the reply does not decode: '
                           f'{error}') from None


def open_runner(config) -> TransactionRunner:
    """Open the bus's port (exclusively) and return a transaction runner on it."""
    transport = config.make_transport()
    transport.connect()
    return TransactionRunner(transport, config.timing.frame_gap_s)


def parse_parameter_number(text: str) -> int:
    """Return the number of ``3-41`` (FC style: 341), ``16-14`` (1614) or ``205``."""
    group, dash, index = text.partition('-')
    try:
        if dash:
            if not index.isdigit() or len(index) != 2:
                raise ValueError
            return int(group) * 100 + int(index)
        return int(text)
    except ValueError:
        raise CliError(f'parameter number {text!r}: write it as in the manual, e.g. 3-41, '
                       '16-14 or 205', EXIT_USAGE) from None


def parameter_options(args: argparse.Namespace) -> ParameterOptions:
    """Return the drive parameter options given (type, conversion index, array index)."""
    return ParameterOptions(data_type=getattr(args, 'type', None),
                            conversion=getattr(args, 'conversion', None),
                            index=getattr(args, 'index', None))


def with_session(args, action: Callable[[Session], None], writes: bool = False) -> None:
    """Open the bus for the named device, run ``action``, close the bus."""
    config, device, bus = make_bus(args)
    if writes:
        config, device = allow_writes(args, config, device)
    run_session(config, device, bus, action, writes)


def run_session(config, device, bus: Dict[str, Any], action: Callable[[Session], None],
                writes: bool = False) -> None:
    """
    Open the bus for ``device``, run ``action``, close the bus; silence names the address.

    For a command that ``writes``, the device is identified first (reads only): nothing is
    written unless it answers as its family and model.
    """
    session = Session(config, device, bus=bus)
    try:
        if writes:
            session.check_before_writing()
        action(session)
    except NoResponse:
        raise session.silent() from None
    finally:
        session.close()


class Progress:
    """A tqdm bar on stderr while stderr is a terminal: never on stdout, never in a pipe."""

    def __init__(self, total: int, label: str, args, out, unit: str = 'parameter'):
        self.out = out
        self.bar = None
        if not getattr(args, 'quiet', False) and sys.stderr.isatty():
            from tqdm import tqdm
            self.bar = tqdm(total=total, desc=label, unit=f' {unit}', file=sys.stderr,
                            leave=False, dynamic_ncols=True)

    def __enter__(self) -> 'Progress':
        return self

    def __exit__(self, *exc) -> None:
        if self.bar is not None:
            self.bar.close()

    def step(self) -> None:
        """Count one done."""
        if self.bar is not None:
            self.bar.update(1)

    def emit(self, line: str) -> None:
        """Print a result line on ``out`` (the bar, on stderr, is redrawn below it)."""
        if self.bar is not None:
            self.bar.write(line, file=self.out)
        else:
            print(line, file=self.out, flush=True)


# -- status and monitor ---------------------------------------------------------------------
# Details that repeat the state or the trip as the raw code the device gave: the state's
# name and the trip's text are printed instead (as the node publishes them on <name>/state
# and <name>/trip), and an unknown state code is named in a warning line.
RAW_CODE_DETAILS = frozenset({'state_code', 'trip_code_register', 'trip_code_reply',
                              'mcd200_state'})


def trip_text(reading: DeviceReading) -> str:
    """Return the trip as a user reads it: its text and code (the node's trip, trip_code)."""
    if not reading.trip_code and not reading.trip_name:
        return 'none'
    return f'{reading.trip_name or "code not known"} (trip code {reading.trip_code})'


def reading_lines(reading: DeviceReading) -> List[str]:
    """Return a reading as 'key: value' lines, in the words a user reads."""
    lines = [f'state: {reading.state}', f'status word: 0x{reading.status_word:04X}',
             f'trip: {trip_text(reading)}']
    for label, value, unit in (('motor current', reading.motor_current_a, 'A'),
                               ('motor temperature', reading.motor_temperature_pct, '%'),
                               ('speed feedback', reading.speed_feedback_pct, '%')):
        if value is not None:
            lines.append(f'{label}: {value:.1f} {unit}')
    for label, word in (('alarm word', reading.alarm_word),
                        ('warning word', reading.warning_word)):
        if word is not None:
            lines.append(f'{label}: 0x{word:08X}')
    lines += [f'{key}: {value}' for key, value in reading.details.items()
              if key not in RAW_CODE_DETAILS]
    lines += [f'warning: {text}' for text in reading.warnings]
    if reading.fault:
        lines.append(f'fault: {reading.fault}')
    return lines


def command_status(args, out) -> int:
    """Print one device's decoded status."""
    def status(session: Session) -> None:
        lines = reading_lines(session.poll())
        print(f'{session.name}: {session.device.family} {session.profile.model} at address '
              f'{session.device.address}', file=out)
        for line in lines:
            print(f'  {line}', file=out)
    with_session(args, status)
    return EXIT_OK


def command_monitor(args, out) -> int:
    """Print the decoded status once a period until Ctrl-C (or --count polls)."""
    def monitor(session: Session) -> None:
        polls = 0
        while args.count == 0 or polls < args.count:
            started = time.monotonic()
            try:
                line = '  '.join(reading_lines(session.poll())[:6])
            except (TransportError, CliError) as error:
                line = f'no reading: {error}'
            print(f'{time.strftime("%H:%M:%S")}  {line}', file=out, flush=True)
            polls += 1
            if args.count == 0 or polls < args.count:
                time.sleep(max(0.0, args.period - (time.monotonic() - started)))
    with_session(args, monitor)
    return EXIT_OK


# -- get and set ----------------------------------------------------------------------------
def value_line(session: Session, number: int, spec: Optional[ParameterSpec], value: Any,
               suffix: str = '') -> str:
    """Return 'label = value unit  # name (type)' for a parameter value."""
    shown_as = session.label(number)
    about = info.describe(spec, shown_as)
    text = f'{shown_as} = {info.format_value(spec, value, session.factors)}{suffix}'
    return text + (f'  # {about}' if about else '')


def command_get(args, out) -> int:
    """Print one parameter's value."""
    def get(session: Session) -> None:
        number = session.number(args.parameter)
        options = parameter_options(args)
        spec = session.typed_spec(args.parameter, number, options)
        value = session.parameter(number, options=options)
        print(value_line(session, number, spec, value), file=out)
    with_session(args, get)
    return EXIT_OK


def command_set(args, out) -> int:
    """Write one parameter (checked against the model's table first), then read it back."""
    def set_(session: Session) -> None:
        number = session.number(args.parameter)
        options = parameter_options(args)
        spec = session.typed_spec(args.parameter, number, options)
        value = info.parse_value(spec, args.value)
        if spec is not None:
            reason = backup_file.value_reason(spec, value, session.factors)
            if reason:
                raise CliError(f'{reason}: nothing written', EXIT_USAGE)
        session.parameter(number, value, replace(options, eeprom=args.eeprom))
        read = session.parameter(number, options=options)
        if not info.same_value(value, read):
            raise CliError(f'{session.label(number)}: wrote {value!r}, but it reads back '
                           f'{read!r}')
        print(value_line(session, number, spec, read, ' (written, read back)'), file=out)
    with_session(args, set_, writes=True)
    return EXIT_OK


# -- backup and restore ---------------------------------------------------------------------
def backup_rows(session: Session) -> List[Tuple[int, Optional[ParameterSpec]]]:
    """Return (PNU, spec) of each parameter a backup covers, in order."""
    profile = session.require_parameters()
    session.resolve_model()  # model auto: the parameter numbers depend on the model
    numbers = sorted(profile.parameter_numbers())
    if not numbers:
        raise CliError(f'{session.name} ({session.device.family} {profile.model}) has no '
                       'parameters to back up', EXIT_USAGE)
    table = session.table()
    return [(number, table.get(number)) for number in numbers]


def read_all(session: Session, numbers: List[int], label: str, args, out) -> Dict[int, Any]:
    """Read each parameter in ``numbers`` (progress on a terminal)."""
    values = {}
    with Progress(len(numbers), label, args, out) as progress:
        for number in numbers:
            values[number] = session.parameter(number)
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
                           f'{session.label(changed[0])}): run the backup again with the '
                           'device stopped; nothing saved')
        for number, spec in rows:  # a value the table refuses: restore would refuse the file
            reason = spec and backup_file.value_reason(spec, values[number], session.factors)
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
    return {'number': session.manual_number(number),
            'pnu': number, 'name': spec.name if spec is not None else f'parameter {number}',
            'unit': spec.unit if spec is not None else '',
            'value': info.display_value(spec, value, session.factors)}


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
    profile = session.require_parameters()
    model = session.resolve_model()
    reasons = backup_file.kind_reasons(backup, session.device.family, model)
    if reasons:
        refuse_restore(backup, session.name, reasons)
    reasons = backup_file.entry_reasons(backup, session.table(), session.factors,
                                        session.manual_number)
    if reasons:
        refuse_restore(backup, session.name, reasons, len(backup.entries))
    values = backup.values()
    write_all(session, values, ParameterOptions(eeprom=args.eeprom), args, out)
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
                       f'{session.label(number)}: wrote {values[number]!r}, reads '
                       f'{verify[number]!r})')
    print(f'{len(values)} parameters restored to {profile.model} {session.name} and verified',
          file=out)


def write_all(session: Session, values: Dict[int, Any], options: ParameterOptions, args,
              out) -> None:
    """Write ``values`` in order; a failure or Ctrl-C says which were written."""
    numbers = list(values)
    written = 0
    try:
        with Progress(len(numbers), 'writing', args, out) as progress:
            for number in numbers:
                session.parameter(number, values[number], options)
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
               f'{session.manual_number(numbers[0])} to ' \
               f'{session.manual_number(numbers[written - 1])})'
    if written < total:
        current = session.manual_number(numbers[written])
        doubt = ' (its write may or may not have reached the device)' if interrupted else ''
        done += f'; {current}{doubt} and the {total - written - 1} after it were not: ' \
                f'{session.name} now holds a mix, restore the file again'
    return done


# -- scan -----------------------------------------------------------------------------------
def command_scan(args, out) -> int:
    """Try every address in the range; print what answers, with family and model."""
    first, last = parse_range(args.addresses)
    bus = bus_values(args, file_block(args)[0])  # the file's bus, options winning
    families = scan_families(bus)
    if not families:
        raise CliError(f'scan: no family it can identify runs on protocol '
                       f'{bus.get("protocol", "modbus_rtu")!r}', EXIT_USAGE)
    config = cfg.build_config(dict(bus, devices=['probe']),
                              {'probe': {'family': families[0], 'address': first}})
    runner = open_runner(config)  # one port for the whole scan
    found = 0
    try:
        with Progress(last - first + 1, 'scanning', args, out, unit='address') as progress:
            for address in range(first, last + 1):
                result = scan_address(bus, address, runner)
                progress.step()
                if result:
                    found += 1
                    progress.emit(f'address {address}: {result}')
    finally:
        runner.transport.close()
    print(f'{found} device(s) found at addresses {first}-{last}', file=out)
    return EXIT_OK


def scan_families(bus: Dict[str, Any]) -> Tuple[str, ...]:
    """Return the families ``scan`` asks, in order, that can run on the bus's protocol."""
    return tuple(family for family in SCAN_FAMILIES
                 if bus.get('protocol', 'modbus_rtu') in FAMILIES[family].protocols)


def parse_range(text: str) -> Tuple[int, int]:
    """Return (first, last) of ``1-32`` or ``5``."""
    first, _, last = text.partition('-')
    try:
        low, high = int(first), int(last or first)
    except ValueError:
        raise CliError(f'address range {text!r}: write it as 1-32', EXIT_USAGE) from None
    if not 1 <= low <= high <= 247:
        raise CliError(f'address range {text!r} must lie within 1-247, low to high',
                       EXIT_USAGE)
    return low, high


def probe_session(bus: Dict[str, Any], family: str, address: int,
                  runner: TransactionRunner, retries: int = 0) -> Optional[Session]:
    """Return a session with a probe device of ``family`` at ``address``, or None."""
    values = {'family': family, 'address': address,
              'model': 'vlt6000' if family == 'vlt' else 'auto'}
    try:  # scan: no retries, silence at an address means nobody is there
        config = cfg.build_config(dict(bus, devices=['probe'], retries=retries),
                                  {'probe': values})
    except ConfigError:
        return None  # e.g. an MCD cannot sit at this address
    return Session(config, config.devices[0], runner)


def scan_address(bus: Dict[str, Any], address: int, runner: TransactionRunner) -> str:
    """Return what answers at ``address`` in words, or '' if nothing does."""
    found = identify(bus, address, runner)
    return '' if found is None else found.words


class Answer(NamedTuple):
    """What answers at an address, as :func:`identify` tells it."""

    family: Optional[str]  # None: something answers, but as none of the families asked
    words: str  # e.g. 'fc fc51, state ready'
    model: Optional[str] = None  # None: the reads cannot tell (VLT 5000 or 6000)


def other_family(session: Session, found: Answer, tail: str = '') -> str:
    """Return the line that says ``found`` answers at the session's address, not its family."""
    device = session.device
    if found.family is None:
        return f'{session.name}: address {device.address}: {found.words} ({device.family} ' \
            f'included): check --address and --family{tail}'
    return f'{session.name}: address {device.address} answers as {found.words}, not as ' \
        f'family {device.family}: give --family {found.family} (or the right address){tail}'


def identify(bus: Dict[str, Any], address: int, runner: TransactionRunner,
             retries: int = 0) -> Optional[Answer]:
    """
    Return what answers at ``address``, or None if nothing does.

    FC-series drives are asked for their type text (par. 15-40) first, then MCD starters
    for their product word (40007); then the address is probed as a VLT 5000/6000 option
    card (:func:`probe_option_card`). Silence at the first question ends the address (a
    reply lost ``retries`` times over: ``scan`` gives none, a check before a write the
    bus's). Reads only.
    """
    for family in scan_families(bus):
        session = None
        try:
            session = probe_session(bus, family, address, runner, retries)
            if session is None:
                continue
            reading = session.poll()
            unknown = unknown_drive_type(session.profile, reading.state)
            if unknown:
                return Answer('vlt', unknown)
            model = session.profile.model
            if model == 'auto':  # AP ASCII: the starter cannot tell its model
                protocol = bus.get('protocol', 'modbus_rtu')
                return Answer(family, f'{family} (its model cannot be read over {protocol}: '
                                      f'name it with --model), state {reading.state}')
            return Answer(family, f'{family} {model}, state {reading.state}', model)
        except LinkDown as error:
            raise CliError(str(error)) from None
        except NoResponse:
            return None  # nothing at this address: do not try the other families
        except (TransportError, CliError, ModelMismatch, ProtocolError, ValueError,
                IndexError):
            continue
        finally:
            if session is not None:
                session.close()
    card = probe_option_card(bus, address, runner) \
        if bus.get('protocol', 'modbus_rtu') in FAMILIES['vlt'].protocols else ''
    return Answer('vlt', card) if card else \
        Answer(None, 'something answers, but not as any supported family')


def unknown_drive_type(profile, state: str) -> str:
    """Return what an FC-profile drive that does not tell its type is ('' if it does)."""
    if not isinstance(profile, FcProfileDrive) or profile.data.identify_parameter is None:
        return ''
    type_text = profile.identity.get('drive_type', '')
    if profile.data.model_from_type(type_text) is not None:
        return ''
    told = f'par. 15-40 reads {type_text!r}' if type_text and \
        not type_text.startswith('not readable') else 'par. 15-40 not readable'
    return f'a drive that does not tell its FC type ({told}): a VLT 5000/6000? set family ' \
        f'vlt with model vlt5000 or vlt6000, state {state}'


def probe_option_card(bus: Dict[str, Any], address: int, runner: TransactionRunner) -> str:
    """
    Return what a VLT 5000/6000 option card at ``address`` says, or ''.

    The card cannot tell which drive it sits in, so nothing model-specific is asked: the
    FC-profile status coils, then par. 538 (the alarm word, on both models). A refusal with
    one of the card's own codes (00 "no such parameter" ..., which no plain Modbus device
    answers) still marks the card.
    """
    session = probe_session(bus, 'vlt', address, runner)
    if session is None or ReadCoils not in PROTOCOLS[session.config.link.protocol].requests:
        return ''  # the option card speaks Modbus only
    transact = session.runner.transact
    try:
        coils = transact(session.record, ReadCoils(COIL_STATUS, PROCESS_COILS))
        status_word, _ = coils_to_words(coils[:PROCESS_COILS])
        try:
            transact(session.record, ReadRegisters(parameter_address(VLT_COMMON_PARAMETER), 2))
        except DeviceException as error:
            if error.code not in OPTION_CARD_CODES:
                return ''
    except LinkDown as error:
        raise CliError(str(error)) from None
    except (TransportError, ProtocolError, ValueError, IndexError):
        return ''
    finally:
        session.close()
    return 'vlt (VLT 5000/6000 option card: set model vlt5000 or vlt6000), state ' \
        f'{StatusWord(status_word).state(None, False)}'


# -- command line ---------------------------------------------------------------------------
DESCRIPTION = """\
Commission Danfoss soft starters (MCD) and drives (FC 51, VLT 5000/6000) on an RS-485 bus or
Modbus gateway, without ROS. The bus and the device come from the node's parameters file
(--config FILE --device NAME) or from options (--port, --family, --address).

Exit status: 0 done, 1 the bus or the device failed, 2 a bad argument or file,
130 interrupted (Ctrl-C), 141 the reader of stdout went away (| head). Progress is drawn on
stderr only when it is a terminal."""

EXAMPLES = {
    'scan': 'drive-bridge scan --port /dev/ttyUSB0 --addresses 1-32',
    'status': 'drive-bridge status --config config/mixed_bus.yaml --device feeder',
    'get': 'drive-bridge get --port /dev/ttyUSB0 --family fc --address 1 3-41\n'
           '  drive-bridge get --port /dev/ttyUSB0 --family vlt --model vlt5000 --address 5 '
           '205 --type int32 --conversion -3\n'
           '  drive-bridge get --config config/mixed_bus.yaml --device crusher 4',
    'set': 'drive-bridge set --port /dev/ttyUSB0 --family fc --address 1 3-41 4.25\n'
           '  drive-bridge set --port /dev/ttyUSB0 --family vlt --model vlt6000 --address 6 '
           '533 1234567890',
    'backup': 'drive-bridge backup --config config/mixed_bus.yaml --device feeder feeder.yaml',
    'restore': 'drive-bridge restore --config config/mixed_bus.yaml --device feeder '
               'feeder.yaml',
    'monitor': 'drive-bridge monitor --config config/mixed_bus.yaml --device feeder '
               '--count 3',
}

SUBCOMMANDS = {
    'scan': ('find devices in an address range',
             'Ask every address in the range what it is: as an FC-series drive (par. 15-40), '
             'as an MCD starter (product word 40007), then as a VLT 5000/6000 option card '
             '(status coils and par. 538, which both models have; the card cannot tell the '
             'model). An address that stays silent is skipped at once. Reads only.'),
    'status': ('one device, decoded', 'Poll one device once and print its decoded state, '
               'words, readouts and diagnostics. Reads only.'),
    'get': ('read a parameter by its manual number',
            'Read one parameter. Numbers as the manual writes them: FC 3-41 or 16-14, VLT '
            "205, MCD 4 (the Modbus Module's parameter number) or its designation (1-4). "
            'Values in display units (the conversion index applied), with the unit and the '
            'table entry. A number outside the built-in table needs --type and '
            '--conversion (drives). Reads only (a VLT text parameter writes the index '
            'register IND first).'),
    'set': ('write a parameter, then read it back',
            'Write one parameter and read it back. The value is checked first against the '
            "model's table (type, limits, options), and the device at the address is asked "
            'what it is, with reads only as scan asks: nothing is written if the value does '
            'not fit or the device does not answer as the family and model given. A text '
            'parameter takes the value as text (1234567890 stays text). Process data and '
            'control registers (FC 51 50000 CTW ...) are no parameters and are refused: use '
            "the node's commands. A device configured allow_control: false is refused unless "
            '--force is given.'),
    'backup': ('save all parameters to YAML and verify',
               "Read every setting of the device (drives: the settings of the model's "
               "table; MCD: parameters 1 to the model's last), read them all again, and "
               'save them if nothing changed in between. The file names the device, model, '
               'address and date, and for each parameter its number, PNU, name, unit and '
               'value; its first lines give the whole command that restores it. FILE must be '
               'new (--force overwrites it). Reads only.'),
    'restore': ('write a YAML backup back and verify',
                'Check the whole file first and write nothing unless all of it fits: family '
                'and model (never overridable), device name and address (--force to restore '
                "another device's backup), every number in the model's table and a "
                'setting, every value within its type, limits and options; and ask the device '
                'at the address what it is (reads only, as scan asks): nothing is written '
                'unless it answers as the family and model given. Then write each parameter '
                "in the file's order and read every one back. A failure or Ctrl-C part-way "
                'says which parameters were written.'),
    'monitor': ('live decoded status (Ctrl-C ends)',
                'Poll the device once a period and print one line each time, until Ctrl-C '
                '(exit status 130) or --count polls. Reads only.'),
}


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser of ``drive-bridge``."""
    parser = argparse.ArgumentParser(
        prog='drive-bridge', description=DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog='examples:\n' + '\n'.join(f'  {EXAMPLES[name]}' for name in
                                         ('scan', 'get', 'set', 'backup', 'restore'))
        + '\n\n"drive-bridge COMMAND --help" tells more of each command.')
    commands = parser.add_subparsers(dest='command', required=True, metavar='COMMAND')
    add = _subcommand_adder(commands)
    scan = add('scan', command_scan, device=False)
    scan.add_argument('--addresses', default='1-32', help='address range (default 1-32)')
    add('status', command_status)
    get = add('get', command_get)
    get.add_argument('parameter', help='number as in the manual: FC 3-41, VLT 205, MCD 4 or 1-4')
    _parameter_options(get)
    set_ = add('set', command_set, writes=True)
    set_.add_argument('parameter', help='number as in the manual: FC 3-41, VLT 205, MCD 4')
    set_.add_argument('value', help='in display units (3.5 for 3.5 s), or the text of a text '
                      'parameter')
    _eeprom_option(set_)
    _parameter_options(set_)
    backup = add('backup', command_backup)
    backup.add_argument('file', help='the YAML file to write (a new file, unless --force)')
    backup.add_argument('--force', action='store_true', help='overwrite FILE if it exists')
    restore = add('restore', command_restore, writes=True)
    restore.add_argument('file', help='a backup written by drive-bridge backup')
    _eeprom_option(restore)
    monitor = add('monitor', command_monitor)
    monitor.add_argument('--period', type=positive_seconds, default=0.5,
                         help='seconds between polls (default 0.5)')
    monitor.add_argument('--count', type=poll_count, default=0,
                         help='stop after N polls (0: never)')
    return parser


def positive_seconds(text: str) -> float:
    """Return ``text`` as a positive, finite number of seconds (an argparse type)."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f'{text!r} is not a positive number of seconds')
    return value


def poll_count(text: str) -> int:
    """Return ``text`` as a whole number, 0 or more (an argparse type)."""
    if not text.isdigit():
        raise argparse.ArgumentTypeError(f'{text!r} is not a whole number, 0 or more')
    return int(text)


def _subcommand_adder(commands):
    def add(name: str, function, device: bool = True, writes: bool = False):
        summary, description = SUBCOMMANDS[name]
        sub = commands.add_parser(
            name, help=summary, description=textwrap.fill(description, 79),
            epilog=f'example:\n  '
            f'{EXAMPLES[name]}', formatter_class=argparse.RawDescriptionHelpFormatter)
        sub.set_defaults(function=function)
        bus = sub.add_argument_group('bus (default: from --config, else the node defaults)')
        bus.add_argument('--config', metavar='FILE',
                         help="the node's parameters file (YAML); options given here win")
        bus.add_argument('--node', help='the node block of --config (its full name, e.g. '
                         '/line1/drive_bridge) when the file has several')
        bus.add_argument('--protocol', choices=tuple(PROTOCOLS))
        bus.add_argument('--port', help='serial device or URL (default /dev/ttyUSB0)')
        bus.add_argument('--host', help='gateway host (modbus_tcp, rtu_over_tcp)')
        bus.add_argument('--tcp-port', dest='tcp_port', type=int, help='gateway TCP port')
        bus.add_argument('--baudrate', type=int, help='default 9600')
        bus.add_argument('--parity', choices=('N', 'E', 'O'), help='default E')
        bus.add_argument('--stopbits', type=int, choices=(0, 1, 2),
                         help='0 (default): 2 with no parity, 1 with parity')
        bus.add_argument('--timeout', type=float, help='seconds per transaction (default 0.5)')
        sub.add_argument('--quiet', action='store_true', help='no progress bar and no notes '
                         '(such as the pty note); warnings and errors still print')
        if device:
            chosen = sub.add_argument_group('device')
            chosen.add_argument('--device', help='device name in --config (default: the '
                                'first)')
            chosen.add_argument('--family', choices=sorted(cfg.FAMILIES))
            chosen.add_argument('--model', help='e.g. fc51, vlt6000, mcd500 (default auto; '
                                'VLT: required)')
            chosen.add_argument('--address', type=int)
        if writes:
            sub.add_argument('--force', action='store_true', help=FORCE_HELP[name])
        return sub
    return add


FORCE_HELP = {
    'set': 'write even though the device is configured allow_control: false (monitor only); '
           'a warning names it',
    'restore': 'restore to a device configured allow_control: false, or a backup taken of '
               'another device name or address (family and model must still match); a '
               'warning says so',
}


def _eeprom_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('--eeprom', action='store_true',
                        help='FC 51 and VLT 5000/6000: store the write in EEPROM as well as '
                        'RAM (coil 65); without it the drive keeps it in RAM only. MCD: does '
                        'not apply')


def _parameter_options(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group('drive parameters outside the built-in table (FC, VLT; '
                                      'MCD registers are raw 16-bit values)')
    group.add_argument('--type', choices=PARAMETER_TYPES,
                       help='data type (manual: "Type")')
    group.add_argument('--conversion', type=int, help='conversion index, e.g. -2 for 0.01')
    group.add_argument('--index', type=int, help='array index of an array parameter')


class _StderrLog(logging.Handler):
    """
    The package's log lines on stderr, as drive-bridge's.

    Notes (INFO: a pty opened without parity) only without ``--quiet``; warnings and
    errors always.
    """

    def __init__(self, quiet: bool = False):
        super().__init__(logging.WARNING if quiet else logging.INFO)

    def emit(self, record: logging.LogRecord) -> None:
        """Print the record's message in one line; a warning or error says so."""
        level = '' if record.levelno < logging.WARNING else f'{record.levelname}: '
        print(f'drive-bridge: {level}{record.getMessage()}', file=sys.stderr, flush=True)


def main(argv: Optional[List[str]] = None, out=sys.stdout) -> int:
    """Run ``drive-bridge``; return the exit status."""
    args = build_parser().parse_args(argv)
    logger = logging.getLogger('drive_bridge')
    handler = _StderrLog(getattr(args, 'quiet', False))
    logger.addHandler(handler)
    level = logger.level
    logger.setLevel(logging.INFO)
    try:
        return run_command(args, out)
    finally:
        logger.removeHandler(handler)
        logger.setLevel(level)


def run_command(args: argparse.Namespace, out) -> int:
    """Run the command ``args`` names; return the exit status, with failures in one line."""
    try:
        status = args.function(args, out)
        out.flush()  # a reader that went away shows here, not when Python exits
        return status
    except CliError as error:
        print(f'drive-bridge: {error}', file=sys.stderr)
        return error.code
    except (ConfigError, CommandRefused) as error:
        print(f'drive-bridge: {error}', file=sys.stderr)
        return EXIT_USAGE
    except (DriveBridgeError, ModelMismatch) as error:
        print(f'drive-bridge: {error}', file=sys.stderr)
        return EXIT_FAILED
    except KeyboardInterrupt:
        print('drive-bridge: interrupted', file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        # The reader went away (`drive-bridge monitor ... | head -3`): the command has ended
        # (a write it made is done: each prints after its transaction).
        drop_stdout()
        return EXIT_BROKEN_PIPE


if __name__ == '__main__':
    sys.exit(main())
