"""
The transport contract: what the bus needs from whatever carries its requests.

A transport owns one link (a serial port, or a TCP connection to a gateway) and runs one
request at a time for the bus thread. Every wait inside :meth:`Transport.execute` is bounded:
a reply window by the transaction's deadline (the link's ``timeout_s`` from the moment the
request is sent); on a line without transaction ids a quarantine follows a failed
transaction, to its deadline and a guard after it, before the error is raised, and one may
go before a request when late bytes wait (:mod:`drive_bridge.transport.exchange`). A line
that keeps talking past a guard is a :class:`~drive_bridge.errors.LineBabble`. Failures are
the typed errors of :mod:`drive_bridge.errors`.
"""

from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List

from drive_bridge.protocol.framing import Frame
from drive_bridge.protocol.requests import Request
from drive_bridge.transport.link import LinkSettings

DEV = '/dev/'  # left out of a serial port's name in a wire trace


@dataclass(frozen=True)
class LineTiming:
    """
    The times of a line that the line discipline keeps, in seconds.

    ``gap_s``: the protocol's inter-frame silence (the end-of-frame check);
    ``quarantine_silence_s``: the silence that ends a quarantine (at least the gap, longer
    where USB adapters deliver bytes in batches); ``guard_s``: how long after a reply window's
    deadline late replies are still waited for; ``paced``: bytes arrive at the wire's pace (a
    real UART), so a reply complete too soon to be ours is not ours. ``echo``: the adapter
    echoes what it sends.
    """

    char_s: float
    gap_s: float
    timeout_s: float
    guard_s: float
    quarantine_silence_s: float
    paced: bool = False
    echo: bool = False


@dataclass
class TransactionReport:
    """
    What a transaction discarded, for the statistics: whole frames and other bytes.

    ``late``: whole valid frames that were not the answer (late replies), each naming its
    unit (None: a frame that names none). ``noise_bytes``: bytes that were no whole frame.
    ``quiet_s``: the silence the transport already kept after the line's last byte when it
    returned (the bus counts it towards the gap before the next request). The round trip
    leaves out ``after_answer_s``, the time from the last byte of the answer to the return
    (the end-of-frame silence, a window held open, a quarantine), and ``held_s``, the time
    earlier windows of the transaction stayed open after their answers and a quarantine
    before the request took.
    """

    late: List[Frame] = field(default_factory=list)
    noise_bytes: int = 0
    quiet_s: float = 0.0
    after_answer_s: float = 0.0
    held_s: float = 0.0


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
        # What the last transaction discarded (late replies by unit, noise).
        self.last_report = TransactionReport()

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
        """
        Run one request with device ``unit``; return what the reply carries.

        A transport of a line without transaction ids returns only a reply that is provably
        the answer, and raises only once the line is quiet again: a transaction that ends
        badly quarantines the line before its error is raised (the line discipline,
        :mod:`drive_bridge.transport.exchange`), so whatever the bus reads after it is fresh.
        """

    def describe(self) -> str:
        """Return the link in words, for messages."""
        return self.settings.describe()

    def start_trace(self, trace) -> None:
        """
        Write every frame of the link to a wire trace (``trace``: its TraceSettings).

        Call before the first transaction, from the thread that will own the link.
        """
        raise NotImplementedError(f'{type(self).__name__} cannot trace its wire')


def trace_interface(settings: LinkSettings) -> str:
    """Return the line's name in a wire trace: the port without /dev/, or host:port."""
    if settings.is_serial:
        port = settings.port
        return port[len(DEV):] if port.startswith(DEV) and len(port) > len(DEV) else port
    return f'{settings.host}:{settings.tcp_port}'


def trace_protocol(settings: LinkSettings) -> str:
    """Return the protocol whose dissector decodes the link's frames in a trace."""
    return 'modbus_rtu' if settings.protocol == 'rtu_over_tcp' else settings.protocol
