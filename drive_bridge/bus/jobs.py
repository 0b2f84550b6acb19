"""
Jobs: the work that goes before polls, each with a deadline, stops first.

A job is a command, a parameter access, a device's set-up writes or the stop of everything
at deactivate and shutdown. Its future is resolved exactly once. A job that has not reached
the wire by its deadline is dropped and answered as failed, and is then never sent: the
bus marks a job running (``Future.set_running_or_notify_cancel``) just before its first
write, so a caller that gave up and cancelled it wins or loses that race atomically.
"""

from collections import deque
from concurrent.futures import Future
from dataclasses import dataclass, field
from typing import Callable, Deque, Iterator, List, Optional, Tuple

from drive_bridge.bus.device import BusDevice
from drive_bridge.devices.contracts import ParameterPlan
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
class ParameterJob(Job):
    """A parameter read or write."""

    plan: Optional[ParameterPlan] = None

    def describe(self) -> str:
        """Return the access in words."""
        return self.plan.label if self.plan else 'parameter'


@dataclass
class SetupJob(Job):
    """The set-up writes of a device that came online."""

    writes: Tuple[Request, ...] = ()

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
    """Two queues: urgent jobs (stops) first, then the others, each in order of arrival."""

    def __init__(self):
        self._urgent: Deque[Job] = deque()
        self._normal: Deque[Job] = deque()

    def __bool__(self) -> bool:
        """Return whether a job waits."""
        return bool(self._urgent or self._normal)

    def __iter__(self) -> Iterator[Job]:
        """Iterate over the waiting jobs, urgent first."""
        yield from self._urgent
        yield from self._normal

    def push(self, job: Job) -> None:
        """Queue ``job`` behind the others of its kind."""
        (self._urgent if job.urgent else self._normal).append(job)

    def push_front(self, job: Job) -> None:
        """Queue ``job`` before every other."""
        self._urgent.appendleft(job)

    def pop(self, urgent_only: bool = False) -> Optional[Job]:
        """Return the next job (urgent first), or None."""
        if self._urgent:
            return self._urgent.popleft()
        if self._normal and not urgent_only:
            return self._normal.popleft()
        return None

    def remove(self, keep: Callable[[Job], bool]) -> List[Job]:
        """Remove and return the waiting jobs for which ``keep`` is false."""
        removed = []
        for queue in (self._urgent, self._normal):
            kept = []
            for job in queue:
                (kept if keep(job) else removed).append(job)
            queue.clear()
            queue.extend(kept)
        return removed
