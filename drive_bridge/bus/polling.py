"""
The poll scheduler: which device is due, and its poll cycle one transaction at a time.

:class:`PollScheduler` runs the poll cycle in progress one step at a time (the master puts
commands between the steps), retries a lost or garbled read (never a write), and otherwise
begins the cycle of the device due first. What each outcome means for the device's health
is the :class:`~drive_bridge.bus.health.HealthKeeper`'s; a device whose set-up writes are
due (it came online, or a lost set-up reply is to be sent again) gets them queued as a job.

A LinkDown is not a poll's business: it goes up to the master, which takes the link down;
the link then tells this scheduler (:meth:`PollScheduler.link_lost`).
"""

from typing import Optional

from drive_bridge.bus.device import BusDevice
from drive_bridge.bus.health import HealthKeeper
from drive_bridge.bus.jobs import setup_job
from drive_bridge.bus.runner import DECODE_ERRORS, optional_failure, PollRun
from drive_bridge.bus.seams import JobSink, Transactions
from drive_bridge.bus.table import DeviceTable
from drive_bridge.devices.contracts import PollStep
from drive_bridge.errors import LinkDown, ModelMismatch, MonitorOnly, ProtocolError, TransportError

IDLE_WAIT_S = 0.1  # without devices, the bus looks for work this often


class PollScheduler:
    """Run poll cycles step by step and choose the next one; see the module docstring."""

    def __init__(self, runner: Transactions, devices: DeviceTable, health: HealthKeeper,
                 jobs: JobSink):
        self.runner = runner
        self.devices = devices
        self.health = health
        self.jobs = jobs
        self.current: Optional[PollRun] = None  # the poll cycle in progress

    def run_next(self, now_s: float) -> float:
        """
        Run the next step of the cycle in progress, else the first of the device due.

        Returns 0 after a step, else how long until a device is due. Raises LinkDown.
        """
        if self.current is not None:
            self._step(self.current)
            return 0.0
        device = self.devices.next_due()
        if device is None:
            return IDLE_WAIT_S
        wait_s = device.health.next_due_s - now_s
        if wait_s > 0:
            return wait_s
        self._begin(device, now_s)
        return 0.0

    def abandon(self) -> None:
        """Drop the cycle in progress, if any."""
        poll, self.current = self.current, None
        if poll is not None:
            poll.abandon()

    # -- what the link tells ---------------------------------------------------------
    def link_lost(self, reason: str) -> None:
        """Drop the cycle in progress and take every device offline."""
        self.abandon()
        self.health.mark_all_offline(reason)

    def link_opened(self) -> None:
        """Make every device due now."""
        self.devices.all_due()

    # -- a cycle ---------------------------------------------------------------------
    def _begin(self, device: BusDevice, now_s: float) -> None:
        with self.devices.locked():
            device.health.schedule_next(device.poll_period_s, now_s)
        self.current = PollRun(device, device.profile.poll(device.owner, now_s), now_s)
        self._step(self.current)

    def _step(self, poll: PollRun) -> None:
        device = poll.device
        try:
            step = poll.next_step()
        except ModelMismatch as error:
            self.current = None
            self.health.misconfigured(device, error)
            return
        except DECODE_ERRORS as error:
            self.current = None
            self.health.poll_failed(device, ProtocolError(f'cannot decode reply: {error}'))
            return
        if step is None:
            self._done(poll)
            return
        try:
            result = self.runner.transact(device, step.request)
        except MonitorOnly as error:
            self._refused_write(poll, step, error)
            return
        except LinkDown:
            raise  # the master takes the link down
        except TransportError as error:
            self._step_failed(poll, step, error)
            return
        self.health.answered(device)
        poll.deliver(result, self.runner.last_end_s)

    def _done(self, poll: PollRun) -> None:
        self.current = None
        device = poll.device
        if self.health.poll_succeeded(device, poll.reading, poll.started_s, poll.received_s):
            job = setup_job(device)
            if job is not None:
                self.jobs.push(job)

    def _refused_write(self, poll: PollRun, step: PollStep, error: MonitorOnly) -> None:
        if step.optional:
            poll.deliver(error)
            return
        self.abandon()
        self.health.poll_failed(poll.device, error)

    def _step_failed(self, poll: PollRun, step: PollStep, error: TransportError) -> None:
        if self.health.retry(poll.device, step, poll.attempt, error):
            poll.attempt += 1
            return
        if optional_failure(step, error):
            poll.deliver(error)
            return
        self.abandon()
        self.health.poll_failed(poll.device, error)
