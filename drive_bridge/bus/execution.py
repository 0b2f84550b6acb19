"""
Carrying out the jobs: commands through the motor-state owner, stop-all, parameters, set-up.

:class:`JobRunner` is the part of the bus that writes. A command is admitted by its
device's motor-state owner (:mod:`.motor`) when it is queued and again just before it is sent;
its writes are built at that moment from what is in force; the owner is told whether they
were acknowledged, refused, or left unanswered, and decides what the device may be doing.
"""

import threading
from typing import Callable, Iterable

from drive_bridge.bus import deadman
from drive_bridge.bus.device import BusDevice
from drive_bridge.bus.events import BusEvent
from drive_bridge.bus.jobs import CommandJob, Job, ParameterJob, SetupJob, StopAllJob
from drive_bridge.bus.link import LinkSupervisor
from drive_bridge.bus.polling import DECODE_ERRORS
from drive_bridge.bus.runner import TransactionRunner
from drive_bridge.errors import (
    CommandRefused, DeviceException, LinkDown, MonitorOnly, ProtocolError, TransportError)
from drive_bridge.protocol.commands import Command

SETUP_RETRY_S = 1.0  # a set-up write whose reply was lost is sent again after this pause


def fail(job: Job, error: Exception) -> None:
    """Answer ``job`` with ``error`` unless its caller gave it up (then it is never sent)."""
    if job.future.set_running_or_notify_cancel():
        job.future.set_exception(error)


class JobRunner:
    """Carry out jobs on the bus thread; see the module docstring."""

    def __init__(self, runner: TransactionRunner, link: LinkSupervisor,
                 clock: Callable[[], float], lock: threading.RLock,
                 emit: Callable[[BusEvent], None], link_lost: Callable[[str], None],
                 devices: Callable[[], Iterable[BusDevice]],
                 commands_enabled: Callable[[], bool]):
        self.runner = runner
        self.link = link
        self.clock = clock
        self.lock = lock
        self.emit = emit
        self.link_lost = link_lost
        self.devices = devices
        self.commands_enabled = commands_enabled

    def admit(self, device: BusDevice, command: Command) -> None:
        """Raise CommandRefused (nothing sent) unless ``command`` may be sent now."""
        if command not in device.profile.commands:
            raise CommandRefused(f'{device.name} ({device.profile.family}) has no '
                                 f'{command.value} command')
        device.owner.admit(command, self.commands_enabled())
        if command.stops and device.owner.holds_run:
            if self.link.error:
                raise CommandRefused(f'{self.link.error}: nothing sent')
            return
        self.check_reachable(device)
        if device.health.misconfigured:
            raise CommandRefused(f'{device.name}: {device.health.misconfigured}: nothing sent')
        reading = device.reading
        if command.may_start and reading is not None and reading.tripped:
            trip = reading.trip_name or 'no trip name'
            raise CommandRefused(f'{device.name} is tripped ({trip}): reset it first; '
                                 'nothing sent')
        device.profile.check_command(command, reading)

    def check_reachable(self, device: BusDevice) -> None:
        if self.link.error:
            raise CommandRefused(f'{self.link.error}: nothing sent')
        if device.health.online is not True:
            raise CommandRefused(f'{device.name} is offline ({device.health.status_text}): '
                                 'nothing sent')

    def run(self, job: Job) -> None:
        if isinstance(job, StopAllJob):
            self._run_stop_all(job)
        elif isinstance(job, CommandJob):
            self._run_command_job(job)
        elif isinstance(job, ParameterJob):
            self._run_parameter_job(job)
        elif isinstance(job, SetupJob):
            self._run_setup_job(job)

    def _run_command_job(self, job: CommandJob) -> None:
        device = job.device
        try:
            with self.lock:  # the state may have changed since the command was queued
                self.admit(device, job.command)
        except CommandRefused as error:
            fail(job, error)
            return
        if not job.future.set_running_or_notify_cancel():
            return  # the caller gave up before it was sent: never sent
        try:
            job.future.set_result(self.execute(device, job.command))
        except (CommandRefused, TransportError) as error:
            job.future.set_exception(error)

    def execute(self, device: BusDevice, command: Command) -> str:
        """Send ``command`` now; return the outcome in words or raise with it."""
        owner = device.owner
        with self.lock:
            plan = device.profile.command_plan(command, owner)  # with what is in force now
            motion_before = owner.motion
            owner.sending(command)
            if command.may_start:
                deadman.feed(device, self.clock())
        try:
            for request in plan.writes:
                self.runner.transact(device, request)
        except (DeviceException, MonitorOnly) as error:
            with self.lock:
                owner.refused(command, motion_before)
            text = error if isinstance(error, MonitorOnly) else \
                f'rejected by {device.name}: {self.runner.explain(device, error)}'
            raise CommandRefused(str(text)) from None
        except TransportError as error:
            with self.lock:
                owner.unanswered(command, motion_before, self.clock())
            if isinstance(error, LinkDown):
                self.link_lost(str(error))
            raise TransportError(
                f'no acknowledgement from {device.name} for {command.value} ({error}); it may '
                'or may not have been executed and is not repeated'
                + ('; the motor counts as possibly running' if command.may_start else '')) \
                from None
        with self.lock:
            owner.acknowledged(command)
            if command.may_start:
                deadman.feed(device, self.clock())
            device.health.next_due_s = self.clock()  # read the new state at once
        return f'{command.value} acknowledged by {device.name} (address {device.spec.unit})'

    def _run_stop_all(self, job: StopAllJob) -> None:
        outcomes = []
        for device in list(self.devices()):
            with self.lock:
                holds_run = device.owner.holds_run
                if holds_run and not device.spec.stop_on_shutdown:
                    device.owner.release('left as it was (stop_on_shutdown is false): the '
                                         'cyclic image is no longer written', self.clock())
                    outcomes.append(f'{device.name}: left running (stop_on_shutdown is '
                                    'false)')
                    continue
            if not holds_run:
                continue
            if self.clock() > job.deadline_s:
                outcomes.append(f'{device.name}: NOT STOPPED: no time left ({job.reason})')
                continue
            if self.link.error:
                outcomes.append(f'{device.name}: NOT STOPPED: {self.link.error}')
                continue
            try:
                outcomes.append(self.execute(device, Command.STOP))
            except (CommandRefused, TransportError) as error:
                outcomes.append(f'{device.name}: stop on {job.reason} failed: {error}')
        if job.future.set_running_or_notify_cancel():
            job.future.set_result(outcomes)

    def _run_parameter_job(self, job: ParameterJob) -> None:
        if not job.future.set_running_or_notify_cancel():
            return
        device = job.device
        results: list = []
        try:
            for request in job.plan.transactions:
                results.append(self.runner.transact(device, request))
        except DeviceException as error:
            job.future.set_exception(CommandRefused(
                f'rejected by {device.name}: {self.runner.explain(device, error)}'))
            return
        except (TransportError, MonitorOnly) as error:
            if isinstance(error, LinkDown):
                self.link_lost(str(error))
            job.future.set_exception(error)
            return
        try:
            job.future.set_result(job.plan.decode(results))
        except DECODE_ERRORS as error:
            job.future.set_exception(ProtocolError(f'{job.plan.label}: cannot decode the '
                                                   f'reply: {error}'))

    def _run_setup_job(self, job: SetupJob) -> None:
        """Send the set-up writes (drives: their comms timeout) each time a device is back."""
        device = job.device
        for write in job.writes:
            try:
                self.runner.transact(device, write)
            except LinkDown as error:
                self.link_lost(str(error))
                return
            except (TransportError, MonitorOnly) as error:
                text = self.runner.explain(device, error) \
                    if isinstance(error, TransportError) else str(error)
                lost = isinstance(error, TransportError) and \
                    not isinstance(error, DeviceException)
                with self.lock:
                    device.setup_error = f'set-up write {write.describe()} failed: {text}' + \
                        ('; it is sent again' if lost else '')
                    if lost:  # a lost reply, not a refusal: try again after a pause
                        device.setup_retry_at_s = self.clock() + SETUP_RETRY_S
                self.emit(BusEvent(device.name, 'notice', message=device.setup_error))
                return
        with self.lock:
            device.setup_error = ''
