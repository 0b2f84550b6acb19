"""
Jobs: the work that goes before polls, each with a deadline, stops first.

A job is a command, a parameter access (a function of the device's
:class:`~drive_bridge.devices.parameter_service.ParameterService`, run on the bus thread:
:mod:`.parameter_line`), a device's set-up writes or the stop of everything at deactivate and
shutdown. Its future is resolved exactly once. A job that has not reached
the wire by its deadline is dropped and answered as failed, and is then never sent: the
bus marks a job running (``Future.set_running_or_notify_cancel``) just before its first
write, so a caller that gave up and cancelled it wins or loses that race atomically.
"""

from collections import deque
from concurrent.futures import Future
from dataclasses import dataclass, field
import math
import threading
from typing import Any, Callable, Deque, List, Optional, Tuple

from drive_bridge.bus.device import BusDevice
from drive_bridge.devices.contracts import SetupWrites
from drive_bridge.errors import CommandExpired, CommandRefused
from drive_bridge.protocol.commands import Command
from drive_bridge.protocol.requests import Request


@dataclass
class Job:
    """One piece of work for the bus thread; ``deadline_s`` on the bus's clock."""

    device: Optional[BusDevice]
    deadline_s: float
    future: Future = field(default_factory=Future)

    @property
    def urgent(self) -> bool:
        """Return whether the job goes before every other (stops)."""
        return False

    def describe(self) -> str:
        """Return the job in words."""
        return type(self).__name__


@dataclass
class CommandJob(Job):
    """A command for one device."""

    command: Command = Command.STOP
    internal: str = ''  # who asked, when not a caller (deadman, shutdown)

    @property
    def urgent(self) -> bool:
        """Return whether the command stops a motor."""
        return self.command.stops

    def describe(self) -> str:
        """Return the command in words."""
        return self.command.value


@dataclass
class ParameterServiceJob(Job):
    """
    A parameter access: ``action`` is given the device's ParameterService on the bus thread.

    Its result (or what it raises) resolves the future. It runs between two transactions of
    the bus, and its transactions go back to back; it must do nothing but use the service
    (no waiting of its own).
    """

    action: Optional[Callable[[Any], Any]] = None
    label: str = 'parameter access'

    def describe(self) -> str:
        """Return the access in words."""
        return self.label


@dataclass
class SetupJob(Job):
    """The set-up writes of a device that came online."""

    writes: Tuple[Request, ...] = ()
    labels: Tuple[str, ...] = ()  # what each write sets, in words (par. 8-03 ... = 5.5)

    def describe(self) -> str:
        """Return the job in words."""
        return 'set-up writes'


@dataclass
class StopAllJob(Job):
    """Stop every motor that may run because of the bridge (deactivate, shutdown)."""

    reason: str = 'shutdown'
    per_stop_timeout_s: float = 1.0

    @property
    def urgent(self) -> bool:
        """Return True: it goes first."""
        return True

    def describe(self) -> str:
        """Return the job in words."""
        return f'stop everything ({self.reason})'


class JobQueue:
    """
    The waiting jobs: stops first, then the others, each in order of arrival (any thread).

    The queue keeps its rules itself: a caller's stop for a device drops the starts for it
    that wait (they would otherwise go after the stop and run the motor it was meant to
    stop), a job past its deadline is dropped, and every job that is not a stop can be
    dropped at once (deactivate, shutdown). A dropped job is answered as not sent, outside
    the queue's lock. The bus thread waits on the queue: a caller's job wakes it.
    """

    def __init__(self):
        self._urgent: Deque[Job] = deque()
        self._normal: Deque[Job] = deque()
        self._lock = threading.Lock()
        self._woken = threading.Event()

    def wait(self, timeout_s: float) -> None:
        """Wait up to ``timeout_s`` for a caller's job or a :meth:`wake` (the bus thread)."""
        self._woken.wait(timeout_s)
        self._woken.clear()

    def wake(self) -> None:
        """End the bus thread's wait now (a caller's job, a new setting, the end)."""
        self._woken.set()

    def push(self, job: Job) -> None:
        """Queue ``job`` behind the others of its kind (the bus's own: set-up, deadman)."""
        with self._lock:
            (self._urgent if job.urgent else self._normal).append(job)

    def submit(self, job: Job) -> None:
        """Queue a caller's ``job``; a caller's stop drops the starts it overtakes, unsent."""
        with self._lock:
            overtaken = self._remove(lambda old: not _overtaken_by(job, old)) \
                if isinstance(job, CommandJob) and job.command.stops else []
            (self._urgent if job.urgent else self._normal).append(job)
        self.wake()
        for old in overtaken:
            fail(old, CommandRefused(f'{old.describe()} not sent: a {job.describe()} for '
                                     f'{job.device.name} came after it'))

    def push_front(self, job: Job) -> None:
        """Queue ``job`` before every other."""
        with self._lock:
            self._urgent.appendleft(job)
        self.wake()

    def pop(self) -> Optional[Job]:
        """Return the next job (urgent first), or None."""
        with self._lock:
            if self._urgent:
                return self._urgent.popleft()
            if self._normal:
                return self._normal.popleft()
            return None

    def expire(self, now_s: float) -> None:
        """Drop the jobs past their deadline, answered as expired (a stop-all never expires)."""
        with self._lock:
            expired = self._remove(lambda job: now_s <= job.deadline_s or
                                   isinstance(job, StopAllJob))
        for job in expired:
            fail(job, CommandExpired(
                f'{job.describe()} not sent: the bus did not get to it within its deadline '
                f'({job.deadline_s - now_s:+.2f} s); it is dropped and never sent'))

    def drop_all_but_stops(self, reason: str) -> None:
        """Drop every waiting job that is not a stop, answered as not sent for ``reason``."""
        with self._lock:
            dropped = self._remove(lambda job: job.urgent)
        for job in dropped:
            fail(job, CommandRefused(f'{job.describe()} not sent: {reason} came first, and '
                                     'from then on only stops are taken'))

    def _remove(self, keep: Callable[[Job], bool]) -> List[Job]:
        """Remove and return the waiting jobs for which ``keep`` is false (lock held)."""
        removed = []
        for queue in (self._urgent, self._normal):
            kept = []
            for job in queue:
                (kept if keep(job) else removed).append(job)
            queue.clear()
            queue.extend(kept)
        return removed


def _overtaken_by(stop: CommandJob, job: Job) -> bool:
    """Return whether ``job`` is a start for the device that ``stop`` is for."""
    return isinstance(job, CommandJob) and job.device is stop.device and job.command.may_start


def fail(job: Job, error: Exception) -> None:
    """Answer ``job`` with ``error`` unless its caller gave it up (then it is never sent)."""
    if job.future.set_running_or_notify_cancel():
        job.future.set_exception(error)


def setup_job(device: BusDevice) -> Optional[SetupJob]:
    """Return the job of a device's set-up writes; None without any, or for monitor only."""
    if isinstance(device.profile, SetupWrites) and device.owner.writes_allowed:
        writes = tuple(device.profile.setup_plan())
        if writes:
            return SetupJob(device, math.inf, Future(), writes,
                            tuple(device.profile.setup_labels()))
    return None
