"""
The transport contract: what the bus needs from whatever carries its requests.

A transport owns one link (a serial port, or a TCP connection to a gateway) and runs one
request at a time for the bus thread. Every wait inside :meth:`Transport.execute` is bounded
by the transaction's deadline (the link's ``timeout_s`` from the moment the request is
sent): a line that keeps talking past it is a :class:`~drive_bridge.errors.LineBabble`.
Failures are the typed errors of :mod:`drive_bridge.errors`.
"""

from abc import ABC, abstractmethod
from typing import Any, Callable, Dict

from drive_bridge.protocol.requests import Request
from drive_bridge.transport.link import LinkSettings


def _nothing() -> None:
    """Do nothing: the default of :attr:`Transport.on_request_sent`."""


class Transport(ABC):
    """One link, one request at a time; see the module docstring."""

    #: Whether :meth:`execute` calls :attr:`on_request_sent` each time it has written a
    #: request, before it waits for the reply. The bus then does work that may wait (giving
    #: its listener the readings) on the wire's time, not in the silence before the next
    #: frame; with a transport that does not, it does that work after each transaction.
    reports_request_sent = False

    def __init__(self, settings: LinkSettings):
        self.settings = settings
        # Failures the transport recovered from by itself in the last transaction, by kind
        # (AP ASCII NAKs that a retry from the address fragment answered).
        self.last_recovered: Dict[str, int] = {}
        # Called with no arguments once a request has left (see reports_request_sent); it
        # must not raise.
        self.on_request_sent: Callable[[], None] = _nothing

    @property
    @abstractmethod
    def connected(self) -> bool:
        """Return whether the link is open."""

    @abstractmethod
    def connect(self) -> None:
        """Open the link; raise LinkDown with the reason in words."""

    @abstractmethod
    def close(self) -> None:
        """Close the link (idempotent)."""

    @abstractmethod
    def execute(self, unit: int, request: Request) -> Any:
        """Run one request with device ``unit``; return what the reply carries."""

    def describe(self) -> str:
        """Return the link in words, for messages."""
        return self.settings.describe()
