"""
The job runner: each job to the part that carries it out, on the bus thread.

Commands and the stop of everything go to the :class:`~drive_bridge.bus.execution.
CommandExecutor`; parameter accesses to the device's parameter service on the bus
(:class:`~drive_bridge.bus.parameter_line.ParameterLines`); set-up writes are run here.
While the link is down nothing can be sent, and every job is answered at once
(:meth:`JobRunner.run_while_down`).
"""

from typing import Callable

from drive_bridge.bus.events import Notice
from drive_bridge.bus.execution import CommandExecutor
from drive_bridge.bus.jobs import CommandJob, fail, Job, ParameterServiceJob, SetupJob, StopAllJob
from drive_bridge.bus.parameter_line import ParameterLines
from drive_bridge.bus.seams import EventSink, LinkState, Transactions
from drive_bridge.bus.table import DeviceTable
from drive_bridge.errors import (
    CommandRefused, DeviceException, LinkDown, MonitorOnly, TransportError)

SETUP_RETRY_S = 1.0  # a set-up write whose reply was lost is sent again after this pause


class JobRunner:
    """Carry out jobs by their type; see the module docstring."""

    def __init__(self, runner: Transactions, commands: CommandExecutor, devices: DeviceTable,
                 link: LinkState, events: EventSink, clock: Callable[[], float]):
        self.runner = runner
        self.commands = commands
        self.devices = devices
        self.link = link
        self.events = events
        self.clock = clock
        self.parameters = ParameterLines(runner, link)

    def run(self, job: Job) -> None:
        """Carry out ``job`` now."""
        handlers = {CommandJob: self.commands.run, StopAllJob: self.commands.stop_all,
                    ParameterServiceJob: self.parameters.run, SetupJob: self._run_setup}
        handlers[type(job)](job)

    def run_while_down(self, job: Job) -> None:
        """Answer ``job`` while the link is down: nothing is sent."""
        if isinstance(job, StopAllJob):
            self.commands.stop_all(job)  # each motor that may run: NOT STOPPED, with the reason
        else:
            fail(job, CommandRefused(f'{self.link.error}: nothing sent'))

    def _run_setup(self, job: SetupJob) -> None:
        """Send the set-up writes (drives: their comms timeout) each time a device is back."""
        device = job.device
        labels = job.labels or tuple(write.describe() for write in job.writes)
        for write, label in zip(job.writes, labels):
            try:
                self.runner.transact(device, write)
            except LinkDown as error:
                self.link.lost(str(error))
                return
            except (TransportError, MonitorOnly) as error:
                self._setup_failed(job, label, error)
                return
        with self.devices.locked():
            device.setup_error = ''

    def _setup_failed(self, job: SetupJob, label: str, error: Exception) -> None:
        device = job.device
        text = self.runner.explain(device, error) \
            if isinstance(error, TransportError) else str(error)
        lost = isinstance(error, TransportError) and not isinstance(error, DeviceException)
        with self.devices.locked():
            device.setup_error = f'set-up write {label} failed: {text}' + \
                ('; it is sent again' if lost else '')
            if lost:  # a lost reply, not a refusal: try again after a pause
                device.setup_retry_at_s = self.clock() + SETUP_RETRY_S
        self.events.emit(Notice(device=device.name, stamp_s=self.clock(),
                                message=device.setup_error))
