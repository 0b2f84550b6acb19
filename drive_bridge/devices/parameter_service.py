"""
One device's parameters, for the CLI and the node alike: list, read, write with read-back.

:class:`ParameterService` knows what the device's profile and tables say (numbers as the
manual writes them, specs with types, conversions, limits and options) and turns each
access into the profile's plan; no I/O here. The plan goes to the wire through a seam the
caller implements, :class:`DeviceLine` (a :class:`typing.Protocol`; nothing needs to
inherit from it; not :class:`drive_bridge.bus.seams.Transactions`, which runs one request
for any device of a bus):

``writes_allowed``
    False for a monitor-only device (``allow_control: false``): the service refuses every
    write with :class:`~drive_bridge.errors.MonitorOnly` before anything is sent.
``run(requests, doing)``
    Run the requests in order for this device and return their results; ``doing`` says
    what they are for (``par. 3-41 ...``), for the line's own failure words. Whatever it
    raises passes through the service unchanged, but in a write's read back (the project's
    errors there: ReadBackFailed) (the CLI's line raises its own errors; a
    bus's raises the project's, :mod:`drive_bridge.errors`:
    :class:`drive_bridge.bus.parameter_line.BusDeviceLine`, the node's way).
``check_before_writing()``
    Called before every plan that writes, before anything of it is sent: raise if the
    device at the address must not be written (the CLI asks what answers there, once,
    with reads only; the bus, whose polls know the device, does nothing).
``resolve_model()``
    Return the device's model, with model ``auto`` learned from the device first (the CLI
    polls once; the bus answers from its polls, or raises until the first one). The tables
    depend on it.

The service raises the project's errors: :class:`~drive_bridge.errors.CommandRefused` for
what it refuses before sending (no parameter access, a number or value that does not fit,
:class:`~drive_bridge.errors.MonitorOnly`), :class:`~drive_bridge.errors.ProtocolError`
for a reply that does not decode, :class:`~drive_bridge.errors.ReadBackMismatch` for a
written value that reads back different (with the value read),
:class:`~drive_bridge.errors.ReadBackFailed` for a written value whose read back failed. A
caller turns them into its own words (the CLI prints them in one line, with its exit codes;
the node answers the set with them).

Use: ``service = ParameterService(name, profile, line)``; ``service.table()`` lists the
tabled parameters (PNU -> :class:`~drive_bridge.devices.parameters.ParameterSpec`);
``service.number('3-41')`` turns the manual's designation into the PNU;
``service.read(number)`` reads one; ``service.write(number, value, ParameterOptions(
eeprom=True))`` checks the value against the table, writes it (RAM, or EEPROM as well),
reads it back and returns what it reads. Identification is
:mod:`drive_bridge.devices.identification`.
"""

from dataclasses import replace
from typing import Any, Dict, List, Optional, Protocol, Sequence

from drive_bridge.console import parse_integer
from drive_bridge.devices import mcd_parameters
from drive_bridge.devices import parameter_info as info
from drive_bridge.devices.contracts import DeviceProfile, ParameterAccess, ParameterOptions
from drive_bridge.devices.fc_profile_drive import FcProfileDrive
from drive_bridge.devices.parameters import check_value, ParameterSpec, Value
from drive_bridge.errors import (
    CommandRefused, DriveBridgeError, MonitorOnly, ProtocolError, ReadBackFailed, ReadBackMismatch)
from drive_bridge.protocol.requests import Request


class DeviceLine(Protocol):
    """One device's way to the wire, as parameter access sees it; see the module docstring."""

    @property
    def writes_allowed(self) -> bool:
        """Return False for a monitor-only device: nothing may be written to it."""

    def run(self, requests: Sequence[Request], doing: str) -> List[Any]:
        """Run ``requests`` in order for the device; return their results."""

    def check_before_writing(self) -> None:
        """Raise if the device at the address must not be written (nothing sent yet)."""

    def resolve_model(self) -> str:
        """Return the device's model, learned from the device if configured ``auto``."""


class ParameterService:
    """The parameters of one device over a :class:`DeviceLine`; see the module docstring."""

    def __init__(self, name: str, profile: DeviceProfile, line: DeviceLine):
        self.name = name
        self.profile = profile
        self.line = line
        self._table: Optional[Dict[int, ParameterSpec]] = None
        self._table_model = ''

    def require(self) -> ParameterAccess:
        """Return the profile if it has parameter access; else raise CommandRefused."""
        if not isinstance(self.profile, ParameterAccess):
            raise CommandRefused(f'{self.name} ({self.profile.family}) has no parameter '
                                 'access')
        return self.profile

    # -- what is known of the parameters (no transaction, but model auto's first poll) ----
    def table(self) -> Dict[int, ParameterSpec]:
        """Return what is known of each parameter of the device's model (PNU -> spec)."""
        model = self.line.resolve_model()
        if self._table is None or self._table_model != model:
            self._table = info.parameter_table(self.profile)
            self._table_model = model
        return self._table

    def setting_numbers(self) -> List[int]:
        """Return the numbers of the settings a backup saves, in order."""
        profile = self.require()
        self.line.resolve_model()  # model auto: the numbers depend on the model
        return sorted(profile.parameter_numbers())

    @property
    def factors(self) -> Dict[int, float]:
        """Return the conversion factors of the device's family (index -> factor)."""
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
        model = self.line.resolve_model()
        entry = mcd_parameters.find(model, text)
        if entry is None or entry.serial_number is None:
            known = 'not in the table' if entry is None else 'without a known register'
            raise CommandRefused(f'parameter {text}: {known} of the {model}; give the Modbus '
                                 "Module's parameter number (manual 000 section 6: Parameter "
                                 'N is register 40008 + N), e.g. 4 for 1-4')
        return entry.serial_number

    def spec(self, number: int,
             options: ParameterOptions = ParameterOptions()) -> Optional[ParameterSpec]:
        """Return how ``number`` is read and written with ``options`` (None: not known)."""
        self.require()
        return info.spec_for(self.profile, number, options, self.table())

    # -- transactions ---------------------------------------------------------------------
    def read(self, number: int, options: ParameterOptions = ParameterOptions()) -> Value:
        """Return the value of parameter ``number`` (display units; text as a string)."""
        return self.transfer(number, None, options)

    def write(self, number: int, value: Value,
              options: ParameterOptions = ParameterOptions()) -> Value:
        """
        Write ``value`` to parameter ``number``, read it back, and return what it reads.

        The value is checked first against the table's entry (type, limits, options; a
        number the table lacks is left to the profile): CommandRefused, nothing sent. It
        goes to RAM, or to EEPROM as well with ``options.eeprom``. ReadBackMismatch when the
        device reads back another value (its ``read``), ReadBackFailed when the read back fails
        with one of the project's errors (the line's own errors pass unchanged).
        """
        spec = self.spec(number, options)
        if spec is not None:
            reason = check_value(spec, value, dict(self.factors))
            if reason:
                raise CommandRefused(f'{reason}: nothing written')
        self.transfer(number, value, options)
        try:
            read = self.read(number, replace(options, eeprom=False))
        except DriveBridgeError as error:
            raise ReadBackFailed(f'{self.label(number)}: written, but the read back failed: '
                                 f'{error}') from error
        if not info.same_value(value, read):
            raise ReadBackMismatch(f'{self.label(number)}: wrote {value!r}, but it reads back '
                                   f'{read!r}', read)
        return read

    def transfer(self, number: int, value: Optional[Value] = None,
                 options: ParameterOptions = ParameterOptions()) -> Any:
        """
        Read (``value`` None) or write one parameter as the profile plans it, unchecked.

        Return the value read, or the write's outcome. The table's check and the read-back
        are :meth:`write`'s; a restore checks its whole file first and reads everything back
        after. A monitor-only device gets nothing of a plan that writes (MonitorOnly).
        """
        profile = self.require()
        self.line.resolve_model()  # model auto: the parameter map depends on what it is
        plan = profile.parameter_plan(number, value, options)
        if any(request.writes for request in plan.transactions):
            if not self.line.writes_allowed:  # nothing of the plan sent, from any caller
                raise MonitorOnly(f'{self.name} is monitor only (allow_control: false): '
                                  f'{plan.label} not sent')
            self.line.check_before_writing()  # e.g. a VLT text parameter's index write (IND)
        results = self.line.run(plan.transactions, plan.label)
        try:
            return plan.decode(results)
        except (ValueError, IndexError, TypeError) as error:
            raise ProtocolError(f'{self.name}: {plan.label}: the reply does not decode: '
                                f'{error}') from None


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
        raise CommandRefused(f'parameter number {text!r}: write it as in the manual, e.g. '
                             '3-41, 16-14 or 205') from None
