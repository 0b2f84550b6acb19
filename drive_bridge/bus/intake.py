"""
The job intake: what callers ask for, checked now and queued with a deadline (any thread).

A command is admitted by the command executor (and through it by the device's motor-state
owner) before it is queued, and again on the bus thread just before it is sent; a request
refused here resolves its future at once and sends nothing. Stopping everything goes before
every other job and from then on only stops are taken.
"""

from concurrent.futures import Future
from typing import Any, Callable, Optional, Union

from drive_bridge.bus.execution import CommandExecutor
from drive_bridge.bus.jobs import CommandJob, JobQueue, ParameterJob, StopAllJob
from drive_bridge.bus.table import DeviceTable
from drive_bridge.bus.timing import BusTiming
from drive_bridge.devices.contracts import ParameterAccess, ParameterOptions
from drive_bridge.errors import CommandRefused, MonitorOnly
from drive_bridge.protocol.commands import Command


class JobIntake:
    """Turn callers' requests into jobs on the queue; see the module docstring."""

    def __init__(self, devices: DeviceTable, commands: CommandExecutor, jobs: JobQueue,
                 timing: BusTiming, clock: Callable[[], float]):
        self.devices = devices
        self.commands = commands
        self.jobs = jobs
        self.timing = timing
        self.clock = clock

    def command(self, name: str, command: Union[Command, str],
                deadline_s: Optional[float]) -> Future:
        """Queue ``command`` for device ``name`` (see BusMaster.submit_command)."""
        future: Future = Future()
        try:
            command = Command.parse(command) if isinstance(command, str) else command
            device = self.devices.known(name)
            self.commands.admit(device, command)
            deadline = self.clock() + (self.timing.command_deadline_s if deadline_s is None
                                       else deadline_s)
            self.jobs.submit(CommandJob(device, deadline, future, command))
        except (CommandRefused, ValueError) as error:
            future.set_exception(error if isinstance(error, CommandRefused)
                                 else CommandRefused(str(error)))
        return future

    def parameter(self, name: str, number: int, value: Any,
                  options: ParameterOptions) -> Future:
        """Queue a read (``value`` None) or a write of parameter ``number``."""
        future: Future = Future()
        try:
            device = self.devices.known(name)
            profile = device.profile
            if not isinstance(profile, ParameterAccess):
                raise CommandRefused(f'{name} ({profile.family}) has no parameter access')
            plan = profile.parameter_plan(number, value, options)
            if any(request.writes for request in plan.transactions) and \
                    not device.owner.writes_allowed:
                raise MonitorOnly(f'{name} is monitor only (allow_control is false): '
                                  f'{plan.label} not sent')
            self.commands.check_reachable(device)
            time_s = self.timing.command_deadline_s + \
                len(plan.transactions) * self.timing.transaction_timeout_s
            self.jobs.submit(ParameterJob(device, self.clock() + time_s, future, plan))
        except CommandRefused as error:
            future.set_exception(error)
        return future

    def stop_all(self, reason: str, timeout_s: float) -> Future:
        """Take only stops from now on and queue the stop of everything first."""
        self.refuse(reason)
        job = StopAllJob(None, self.clock() + timeout_s, reason=reason)
        self.jobs.push_front(job)
        return job.future

    def refuse(self, reason: str) -> None:
        """Take only stops from now on; drop waiting jobs that are not stops, unsent."""
        self.commands.enabled = False
        self.jobs.drop_all_but_stops(reason)
