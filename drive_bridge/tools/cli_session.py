"""
What every ``drive-bridge`` command runs on: a session with one device on an open bus.

A :class:`Session` is three collaborators. The session itself is the device's line: it runs
each transaction through the bus's transaction runner, as the node does (a monitor-only
device gets no write, a refusal is explained with the drive's register 7, silence names the
address), and polls. Its :class:`AddressCheck` asks what answers at the address (reads
only, once: :func:`drive_bridge.tools.cli_identify.identify`) when the device answers
as no family should, and before the first write. Its ``parameters``
(:class:`~drive_bridge.devices.parameter_service.ParameterService`) are the device's
parameters over the session, which is their
:class:`~drive_bridge.devices.parameter_service.DeviceLine`. Also here: the errors and
warnings of a command (:class:`Interrupted`, :func:`warn`), ``--force`` on a monitor-only
device (:func:`allow_writes`), opening and closing the bus around a command
(:func:`with_session`, :func:`run_session`), parameter options as typed, and the progress
bar on stderr (:class:`Progress`).
"""

import argparse
from dataclasses import replace
import sys
import time
from typing import Any, Callable, Dict, Optional, Sequence

from drive_bridge.bus.device import BusDevice
from drive_bridge.bus.runner import retryable, run_poll, TransactionRunner
from drive_bridge.config import model as cfg
from drive_bridge.devices.contracts import DeviceReading, ParameterOptions
from drive_bridge.devices.identification import Answer, IDENTIFIED_FAMILIES
from drive_bridge.devices.parameter_service import ParameterService
from drive_bridge.devices.parameters import DATA_TYPES, TEXT
from drive_bridge.errors import (
    DeviceException, LinkDown, ModelMismatch, NoResponse, ProtocolError, TransportError)
from drive_bridge.tools.cli_identify import identify, other_family
from drive_bridge.tools.cli_target import CliError, EXIT_INTERRUPTED, EXIT_USAGE, make_bus


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
    explained as the node explains it (exception 04: register 7 read for the detail). The
    session is its parameters' :class:`~drive_bridge.devices.parameter_service.DeviceLine`.
    """

    def __init__(self, config: cfg.BridgeConfig, device: cfg.DeviceConfig,
                 runner: Optional[TransactionRunner] = None,
                 bus: Optional[Dict[str, Any]] = None):
        self.config = config
        self.device = device
        self.record = BusDevice(device.make_spec(), time.monotonic())
        self.profile = self.record.profile
        self._owns_port = runner is None  # else a port another session opened (scan)
        self.runner = runner or open_runner(config)
        # The bus settings to ask what answers at the address when the device does not
        # answer as its family does, and before the first write (None: never asked).
        self.address_check = AddressCheck(self, bus)
        self.parameters = ParameterService(device.name, self.profile, self)
        self._polled = False

    @property
    def name(self) -> str:
        """Return the device's name."""
        return self.device.name

    @property
    def writes_allowed(self) -> bool:
        """Return False for a monitor-only device (the runner refuses its writes too)."""
        return self.record.owner.writes_allowed

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

    def check_family(self) -> None:
        """Raise a CliError if what answers at the address is not of the device's family."""
        self.address_check.check_family()

    def check_before_writing(self) -> None:
        """Raise a CliError unless the device at the address answers as its family and model."""
        self.address_check.check_before_writing()

    def resolve_model(self) -> str:
        """Return the model; with model auto, poll once so that the device tells it."""
        if self.profile.configured_model == 'auto' and not self._polled:
            self.poll()
        return self.profile.model


class AddressCheck:
    """
    What answers at a session's address, asked once with reads only, and the checks on it.

    Asked (as ``scan`` asks: :func:`~drive_bridge.tools.cli_identify.identify`) when the
    device refuses or garbles what its family is asked, and before the session's first
    write. Without the bus settings (``bus`` None: a probe of ``scan``, which asks that
    itself and never writes) nothing is asked.
    """

    def __init__(self, session: Session, bus: Optional[Dict[str, Any]]):
        self.session = session
        self.bus = bus
        self._answer: Optional[Answer] = None
        self._asked = self._checked = False

    def answer(self) -> Optional[Answer]:
        """Return what answers at the device's address (asked once, reads only)."""
        if not self._asked:
            session = self.session
            self._answer = identify(self.bus, session.device.address, session.runner,
                                    session.config.timing.retries)
            self._asked = True
        return self._answer

    def check_family(self) -> None:
        """
        Raise a CliError if what answers at the address is not of the device's family.

        ``--family mcd`` at an FC 51's address says so, instead of an MCD 200's register
        limits.
        """
        if self.bus is None:
            return
        found = self.answer()
        device = self.session.device
        if found is None or found.family in (None, device.family):
            return
        raise CliError(other_family(self.session.name, device, found), EXIT_USAGE)

    def check_before_writing(self) -> None:
        """
        Raise a CliError unless the device at the address answers as its family and model.

        Asked once, before the session's first write: a write meant for one register map
        never lands in another device's. Families the reads cannot identify (lvsg) are not
        asked; a model the reads cannot tell (VLT 5000 or 6000) is taken as given.
        """
        session = self.session
        device = session.device
        if self._checked or self.bus is None or device.family not in IDENTIFIED_FAMILIES:
            return
        found = self.answer()
        if found is None:
            raise CliError(f'{session.silent("identify it before writing")} Nothing written.')
        if found.family != device.family:
            raise CliError(other_family(session.name, device, found, '; nothing written'),
                           EXIT_USAGE)
        configured = session.profile.configured_model
        if found.model not in (None, configured) and configured != 'auto':
            try:  # the profile decides what fits its model (an MCD 201 answers as a 202)
                session.poll()
            except ModelMismatch:
                raise CliError(f'{session.name}: address {device.address} answers as '
                               f'{found.words}, not as model {configured}: give --model '
                               f'{found.model} (or the right address); nothing written',
                               EXIT_USAGE) from None
        self._checked = True


def open_runner(config) -> TransactionRunner:
    """Open the bus's port (exclusively) and return a transaction runner on it."""
    transport = config.make_transport()
    transport.connect()
    return TransactionRunner(transport, config.timing.frame_gap_s)


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
