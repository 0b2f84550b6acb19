"""
The command executor: commands and the stop of everything, through the motor-state owner.

:class:`CommandExecutor` is the part of the bus that writes commands. A command is admitted by
its device's motor-state owner (:mod:`.motor`) when it is queued and again just before it is
sent; its writes are built at that moment from what is in force; the owner is told whether
they were acknowledged, refused, or left unanswered, and decides what the device may be
doing. The other jobs (parameters, set-up writes) are :mod:`.work`'s.
"""

from typing import Callable, List

from drive_bridge.bus import deadman
from drive_bridge.bus.device import BusDevice
from drive_bridge.bus.jobs import CommandJob, fail, StopAllJob
from drive_bridge.bus.motor import Motion
from drive_bridge.bus.seams import LinkState, Transactions
from drive_bridge.bus.table import DeviceTable
from drive_bridge.errors import (
    AmbiguousReply, CommandRefused, DeviceException, LinkDown, MonitorOnly, TransportError)
from drive_bridge.protocol.commands import Command
from drive_bridge.protocol.requests import Request


class CommandExecutor:
    """Admit and send commands, stop every motor at the end; see the module docstring."""

    def __init__(self, runner: Transactions, devices: DeviceTable, link: LinkState,
                 clock: Callable[[], float]):
        self.runner = runner
        self.devices = devices
        self.link = link
        self.clock = clock
        self.enabled = True  # commands other than stops are taken (the node is active)

    # -- admission (any thread) -----------------------------------------------------------
    def admit(self, device: BusDevice, command: Command) -> None:
        """Raise CommandRefused (nothing sent) unless ``command`` may be sent now."""
        if command not in device.profile.commands:
            raise CommandRefused(f'{device.name} ({device.profile.family}) has no '
                                 f'{command.value} command')
        with self.devices.locked():
            device.owner.admit(command, self.enabled)
            if command.stops and device.owner.holds_run:
                if self.link.error:
                    raise CommandRefused(f'{self.link.error}: nothing sent')
                return
            self.check_reachable(device)
            if device.health.misconfigured:
                raise CommandRefused(f'{device.name}: {device.health.misconfigured}: '
                                     'nothing sent')
            reading = device.reading
            if command.may_start and reading is not None and reading.tripped:
                trip = reading.trip_name or 'no trip name'
                raise CommandRefused(f'{device.name} is tripped ({trip}): reset it first; '
                                     'nothing sent')
            device.profile.check_command(command, reading)

    def check_reachable(self, device: BusDevice) -> None:
        """Raise CommandRefused (nothing sent) if the link is down or the device offline."""
        if self.link.error:
            raise CommandRefused(f'{self.link.error}: nothing sent')
        if device.health.online is not True:
            raise CommandRefused(f'{device.name} is offline ({device.health.status_text}): '
                                 'nothing sent')

    # -- the bus thread -------------------------------------------------------------------
    def run(self, job: CommandJob) -> None:
        """Send a queued command if it is still admitted and its caller still waits."""
        try:
            self.admit(job.device, job.command)  # the state may have changed since queued
        except CommandRefused as error:
            fail(job, error)
            return
        if not job.future.set_running_or_notify_cancel():
            return  # the caller gave up before it was sent: never sent
        try:
            job.future.set_result(self.execute(job.device, job.command))
        except (CommandRefused, TransportError) as error:
            job.future.set_exception(error)

    def execute(self, device: BusDevice, command: Command) -> str:
        """Send ``command`` now; return the outcome in words or raise with it."""
        owner = device.owner
        with self.devices.locked():
            plan = device.profile.command_plan(command, owner)  # with what is in force now
            motion_before = owner.motion
            owner.sending(command)
            if command.may_start:
                deadman.feed(device, self.clock())
        try:
            for request in plan.writes:
                self._write(device, command, request)
        except (DeviceException, MonitorOnly) as error:
            raise self._refused(device, command, motion_before, error) from None
        except TransportError as error:
            raise self._unanswered(device, command, motion_before, error) from None
        with self.devices.locked():
            owner.acknowledged(command)
            if command.may_start:
                deadman.feed(device, self.clock())
            device.health.next_due_s = self.clock()  # read the new state at once
        return f'{command.value} acknowledged by {device.name} (address {device.spec.unit})'

    def _write(self, device: BusDevice, command: Command, request: Request) -> None:
        """
        Send one write of ``command``; a stop whose acknowledgement was ambiguous goes again.

        An ambiguous acknowledgement (one the device may have sent for an earlier request:
        :class:`~drive_bridge.errors.AmbiguousReply`) settles what the device owed, so the
        same write sent once more is answered by its own reply. Only a stop-like command is
        sent again: a stop repeated is harmless, a start never is.
        """
        try:
            self.runner.transact(device, request)
        except AmbiguousReply:
            if not command.stops:
                raise
            self.runner.transact(device, request)

    def _refused(self, device: BusDevice, command: Command, motion_before: Motion,
                 error: Exception) -> CommandRefused:
        with self.devices.locked():
            device.owner.refused(command, motion_before)
        text = error if isinstance(error, MonitorOnly) else \
            f'rejected by {device.name}: {self.runner.explain(device, error)}'
        return CommandRefused(str(text))

    def _unanswered(self, device: BusDevice, command: Command, motion_before: Motion,
                    error: TransportError) -> TransportError:
        with self.devices.locked():
            device.owner.unanswered(command, motion_before, self.clock())
        if isinstance(error, LinkDown):
            self.link.lost(str(error))
        return TransportError(
            f'no acknowledgement from {device.name} for {command.value} ({error}); it may '
            'or may not have been executed and is not repeated'
            + ('; the motor counts as possibly running' if command.may_start else ''))

    def stop_all(self, job: StopAllJob) -> None:
        """Stop every motor that may run because of the bridge; the future gets the outcomes."""
        outcomes: List[str] = []
        for device in self.devices:
            outcome = self._stop_one(job, device)
            if outcome:
                outcomes.append(outcome)
        if job.future.set_running_or_notify_cancel():
            job.future.set_result(outcomes)

    def _stop_one(self, job: StopAllJob, device: BusDevice) -> str:
        """Stop ``device`` if the bridge holds a run for it; return the outcome ('' none)."""
        with self.devices.locked():
            holds_run = device.owner.holds_run
            if holds_run and not device.spec.stop_on_shutdown:
                device.owner.release('left as it was (stop_on_shutdown is false): the '
                                     'cyclic image is no longer written', self.clock())
                return f'{device.name}: left running (stop_on_shutdown is false)'
        if not holds_run:
            return ''
        if self.clock() > job.deadline_s:
            return f'{device.name}: NOT STOPPED: no time left ({job.reason})'
        if self.link.error:
            return f'{device.name}: NOT STOPPED: {self.link.error}'
        try:
            return self.execute(device, Command.STOP)
        except (CommandRefused, TransportError) as error:
            return f'{device.name}: stop on {job.reason} failed: {error}'
