"""
What every ``drive-bridge`` command runs on: a session with one device on an open bus.

:class:`Session` runs each transaction through the bus's transaction runner, as the node
does (a monitor-only device gets no write, a refusal is explained with the drive's register
7), and identifies the device at its address with reads only before its first write.
:func:`identify`, which tells what answers at an address, lives here too: a session asks
it before writing and ``scan`` asks it at every address, and it builds sessions of its own
to ask. Also here: the errors and warnings of a command (:class:`Interrupted`,
:func:`warn`), ``--force`` on a monitor-only device (:func:`allow_writes`), opening and
closing the bus around a command (:func:`with_session`, :func:`run_session`), parameter
numbers and options as typed, and the progress bar on stderr (:class:`Progress`).
"""

import argparse
from dataclasses import replace
import sys
import time
from typing import Any, Callable, Dict, NamedTuple, Optional, Sequence, Tuple

from drive_bridge.bus.device import BusDevice
from drive_bridge.bus.runner import retryable, run_poll, TransactionRunner
from drive_bridge.config import model as cfg
from drive_bridge.console import parse_integer
from drive_bridge.devices import mcd_parameters
from drive_bridge.devices import parameter_info as info
from drive_bridge.devices.contracts import DeviceReading, ParameterAccess, ParameterOptions
from drive_bridge.devices.fc_profile_drive import COIL_STATUS, FcProfileDrive, PROCESS_COILS
from drive_bridge.devices.parameters import DATA_TYPES, parameter_address, ParameterSpec, TEXT
from drive_bridge.devices.registry import FAMILIES
from drive_bridge.errors import (
    ConfigError, DeviceException, LinkDown, ModelMismatch, MonitorOnly, NoResponse,
    ProtocolError, TransportError)
from drive_bridge.protocol.fc_profile import StatusWord
from drive_bridge.protocol.requests import ReadCoils, ReadRegisters
from drive_bridge.protocol.words import coils_to_words
from drive_bridge.tools.cli_target import CliError, EXIT_INTERRUPTED, EXIT_USAGE, make_bus
from drive_bridge.transport.protocols import PROTOCOLS


SCAN_FAMILIES = ('fc', 'mcd')  # asked in this order; then the VLT option card (see scan)
# The families identify() can tell: checked before a write. Not lvsg: behind its gateway
# the starter's process image answers as no family the reads know.
IDENTIFIED_FAMILIES = SCAN_FAMILIES + ('vlt',)
# Exception codes only the VLT option card answers (its drive's FC-protocol error codes and
# its own 64-67, 255); a Modbus device answers 01-0B.
OPTION_CARD_CODES = frozenset({0, 17, 64, 65, 66, 67, 130, 131, 255})
VLT_COMMON_PARAMETER = 538  # the alarm word: both VLT 5000 and VLT 6000 have it
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
            if len(index) != 2 or not (index.isascii() and index.isdigit()):
                raise ValueError
            return parse_integer(group) * 100 + parse_integer(index)
        return parse_integer(text)
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


# -- what answers at an address -----------------------------------------------------------
def scan_families(bus: Dict[str, Any]) -> Tuple[str, ...]:
    """Return the families ``scan`` asks, in order, that can run on the bus's protocol."""
    return tuple(family for family in SCAN_FAMILIES
                 if bus.get('protocol', 'modbus_rtu') in FAMILIES[family].protocols)


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
