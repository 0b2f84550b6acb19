"""
The seams between the bus's parts, as the part on each side sees the other.

:class:`~drive_bridge.bus.master.BusMaster` builds its parts and hands each the others it
needs through these interfaces (constructor injection): no part calls into another's
private methods, and none gets a lock or a callable to reach into another's state.
"""

from typing import Any, Protocol

from drive_bridge.bus.device import BusDevice
from drive_bridge.bus.events import BusEvent
from drive_bridge.bus.jobs import Job
from drive_bridge.errors import TransportError
from drive_bridge.protocol.requests import Request


class EventSink(Protocol):
    """Where the parts put their events (the outbox, :mod:`.outbox`); any thread."""

    def emit(self, event: BusEvent) -> None:
        """Queue ``event`` for the listener."""


class JobSink(Protocol):
    """Where the parts put work of their own (set-up writes, deadman stops): the job queue."""

    def push(self, job: Job) -> None:
        """Queue ``job`` behind the others of its kind (stops first)."""


class Transactions(Protocol):
    """One request at a time on the wire (:class:`~drive_bridge.bus.runner.TransactionRunner`)."""

    last_end_s: float  # the bus clock when the last transaction ended

    def transact(self, device: BusDevice, request: Request) -> Any:
        """Run ``request`` with ``device``; raise MonitorOnly for a write it may not get."""

    def explain(self, device: BusDevice, error: TransportError) -> str:
        """Return a failure in words."""


class LinkState(Protocol):
    """What the job runners see of the link (:class:`~drive_bridge.bus.link.LinkHealth`)."""

    @property
    def error(self) -> str:
        """Return why the link is down ('' while it is up)."""

    def lost(self, reason: str) -> None:
        """Take the link down after a LinkDown: every device goes offline."""


class LinkWatcher(Protocol):
    """Who the link tells when it goes down or comes up (the poll scheduler)."""

    def link_lost(self, reason: str) -> None:
        """Drop the cycle in progress and take every device offline."""

    def link_opened(self) -> None:
        """Make every device due now."""
