"""
The job intake: what callers ask for, checked now and queued with a deadline (any thread).

A command is admitted by the command executor (and through it by the device's motor-state
owner) before it is queued, and again on the bus thread just before it is sent; a request
refused here resolves its future at once and sends nothing. A parameter access is taken
only for a device with parameter access, online, on a link that is up (else refused at once,
nothing sent); it is a function of the device's parameter service, run on the bus thread
(:mod:`.parameter_line`), whose own checks (the table, monitor-only) come before anything of
it is sent. Stopping everything goes before every other job and from then on only stops are
taken.
"""

from concurrent.futures import Future
from typing import Any, Callable, Optional, Union

from drive_bridge.bus.device import BusDevice
from drive_bridge.bus.execution import CommandExecutor
from drive_bridge.bus.jobs import CommandJob, JobQueue, ParameterServiceJob, StopAllJob
from drive_bridge.bus.table import DeviceTable
from drive_bridge.bus.timing import BusTiming
from drive_bridge.devices.contracts import ParameterAccess, ParameterOptions
from drive_bridge.devices.parameter_service import ParameterService
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

    def parameter_service(self, name: str, action: Callable[[ParameterService], Any],
                          deadline_s: Optional[float], label: str = 'parameter access') -> Future:
        """Queue ``action`` for device ``name`` (see BusMaster.run_parameter_service)."""
        future: Future = Future()
        try:
            device = self.devices.known(name)
            _parameter_access(device)
            self.commands.check_reachable(device)
            time_s = self.timing.command_deadline_s + self.timing.transaction_timeout_s \
                if deadline_s is None else deadline_s
            self.jobs.submit(ParameterServiceJob(device, self.clock() + time_s, future, action,
                                                 label))
        except CommandRefused as error:
            future.set_exception(error)
        return future

    def parameter(self, name: str, number: int, value: Any,
                  options: ParameterOptions) -> Future:
        """
        Queue a read (``value`` None) or a write of parameter ``number`` as the profile plans it.

        Unchecked by the table (``ParameterService.transfer``); refused at once, nothing sent,
        for a number or value the profile cannot plan and a write to a monitor-only device.
        """
        try:
            device = self.devices.known(name)
            plan = _parameter_access(device).parameter_plan(number, value, options)
            if any(request.writes for request in plan.transactions) and \
                    not device.owner.writes_allowed:
                raise MonitorOnly(f'{name} is monitor only (allow_control is false): '
                                  f'{plan.label} not sent')
        except CommandRefused as error:
            future: Future = Future()
            future.set_exception(error)
            return future
        time_s = self.timing.command_deadline_s + \
            len(plan.transactions) * self.timing.transaction_timeout_s
        return self.parameter_service(
            name, lambda service: service.transfer(number, value, options), time_s, plan.label)

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


def _parameter_access(device: BusDevice) -> ParameterAccess:
    """Return the device's profile; CommandRefused if it has no parameter access."""
    profile = device.profile
    if not isinstance(profile, ParameterAccess):
        raise CommandRefused(f'{device.name} ({profile.family}) has no parameter access')
    return profile
