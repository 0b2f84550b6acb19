"""
What the native transports share: a byte line, its discipline, and one ``execute``.

A :class:`LineTransport` owns a :class:`~drive_bridge.transport.serial_port.SerialLine` (a
local serial port, or a TCP stream of RTU or FC frames through pyserial's ``socket://``) and
the :class:`~drive_bridge.transport.exchange.LineDiscipline` that runs every transaction on
it with the protocol's framer. A protocol's transport (:mod:`.serial_rtu`, :mod:`.ap_ascii`,
:mod:`.fc_protocol`) says only how its request goes out and whether a frame answers it
(:meth:`LineTransport._run`); the timing of the line, the late replies and the quarantine
are the discipline's, the same for every protocol.
"""

import time
from typing import Any, Callable, ClassVar, Optional, Tuple

from drive_bridge.errors import BadFrame, LinkDown, Nak, NoResponse, TransportError
from drive_bridge.protocol import rtu
from drive_bridge.protocol.framing import Framer
from drive_bridge.transport.base import (
    LineTiming, trace_interface, trace_protocol, TransactionReport, Transport)
from drive_bridge.transport.exchange import ByteLine, LineDiscipline
from drive_bridge.transport.link import LinkSettings, port_missing, pty_device, URL_PREFIXES
from drive_bridge.transport.serial_port import PORT_ERRORS, SerialLine
from drive_bridge.transport.trace_writer import QueuedTrace
from drive_bridge.transport.wire_trace import TraceSettings, WireTrace
import serial

# The shortest silence that ends a quarantine: USB adapters deliver bytes in batches of up to
# 16 ms (the FTDI latency timer), so a shorter pause may be one inside a frame.
QUARANTINE_SILENCE_S = 0.02


def line_port(settings: LinkSettings) -> str:
    """Return the port to open: the serial port, or ``socket://host:port`` for a TCP line."""
    if settings.is_serial:
        return settings.port
    return f'socket://{settings.host}:{settings.tcp_port}'


def paced_line(settings: LinkSettings) -> bool:
    """
    Return whether bytes arrive at the wire's pace: a local serial port that is no pty.

    Only there is a reply complete before the request and it could have crossed the wire
    provably not the answer; ptys and TCP deliver bytes at once, so the check says nothing.
    """
    port = settings.port
    return settings.is_serial and not port.startswith(URL_PREFIXES) and \
        not pty_device(port) and not port_missing(settings)


def line_timing(settings: LinkSettings, paced: Optional[bool] = None) -> LineTiming:
    """
    Return the line discipline's times for ``settings`` (``paced`` None: find out).

    A TCP line of RTU frames keeps no gap between transactions (``frame_gap_s`` 0), but its
    frames came off a serial line behind the gateway: the end-of-frame check waits that
    line's 3.5 characters (at the configured baud rate) for bytes that continue a reply.
    """
    char_s = rtu.character_time_s(settings.baudrate, settings.effective_parity,
                                  settings.effective_stopbits)
    gap_s = settings.frame_gap_s or rtu.frame_gap_s(
        settings.baudrate, settings.effective_parity, settings.effective_stopbits)
    return LineTiming(
        char_s=char_s, gap_s=gap_s, timeout_s=settings.timeout_s, guard_s=settings.guard_s,
        quarantine_silence_s=max(gap_s, QUARANTINE_SILENCE_S),
        paced=paced_line(settings) if paced is None else paced, echo=settings.local_echo)


def line_failure(error: TransportError) -> bool:
    """Return whether ``error`` ended a transaction badly on the line (quarantine it)."""
    return isinstance(error, (NoResponse, BadFrame)) and not isinstance(error, Nak)


class LineTransport(Transport):
    """A transport on a byte line kept by the line discipline; see the module docstring."""

    reports_request_sent = True  # the discipline reports each request as it leaves
    framer: ClassVar[Framer]
    requests: ClassVar[Tuple[type, ...]] = ()

    def __init__(self, settings: LinkSettings,
                 open_port: Callable[..., object] = serial.serial_for_url,
                 paced: Optional[bool] = None, clock: Callable[[], float] = time.monotonic,
                 line: Optional[ByteLine] = None):
        super().__init__(settings)
        # ``line``: another byte line than the serial port (a virtual line on a fake clock)
        self.line = line or SerialLine(settings, line_port(settings), open_port)
        self._paced = paced  # None: whether the port is a real UART, found out at connect
        self.discipline = LineDiscipline(self.line, self.framer,
                                         line_timing(settings, bool(paced)), clock,
                                         self._request_sent)

    @property
    def connected(self) -> bool:
        """Return whether the line is open."""
        return self.line.is_open

    def connect(self) -> None:
        """Open the line; raise LinkDown with the reason in words."""
        self.line.connect()
        if self._paced is None:  # the port exists now: a pty or a UART
            self.discipline.timing = line_timing(self.settings)

    def close(self) -> None:
        """Close the line (idempotent); what the trace has queued is written first."""
        if self.discipline.tracer is not None:
            self.discipline.tracer.trace.drain()
        self.line.close()

    def start_trace(self, trace: TraceSettings) -> None:
        """Trace every frame the line discipline sends and reads (see Transport)."""
        self.discipline.start_trace(QueuedTrace(WireTrace(
            trace, trace_interface(self.settings), trace_protocol(self.settings))))

    def execute(self, unit: int, request) -> Any:
        """Run one request with device ``unit`` under the line discipline; see Transport."""
        self.last_recovered, self.last_report = {}, TransactionReport()
        if not self.line.is_open:
            raise LinkDown('bus offline: not connected')
        if not isinstance(request, self.requests):
            raise TypeError(f'unsupported request {request!r}')
        try:
            return self._transact(unit, request)
        except PORT_ERRORS as error:
            raise self._port_failed(error) from error
        finally:
            self.last_report = self.discipline.report

    def _transact(self, unit: int, request) -> Any:
        discipline = self.discipline
        discipline.begin(unit)
        try:
            result = self._run(unit, request)
        except TransportError as error:
            if line_failure(error):
                discipline.failed(error)
            else:
                discipline.done()
            raise
        discipline.done()
        return result

    def _run(self, unit: int, request) -> Any:
        """Send ``request`` to ``unit`` through the discipline; return what it carries."""
        raise NotImplementedError

    def _request_sent(self) -> None:
        self.on_request_sent()

    def _port_failed(self, error: Exception) -> LinkDown:
        """Close the port after an I/O error and return the LinkDown to raise."""
        self.close()
        if port_missing(self.settings):
            return LinkDown(f'bus offline: {self.settings.port} not found')
        return LinkDown(f'bus offline: {self.settings.describe()}: {error}')
