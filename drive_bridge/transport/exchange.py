"""
The line discipline: one read loop that owns the line's timing, for every serial protocol.

Modbus RTU, AP ASCII and the FC protocol carry no transaction id: a frame of the right
shape may be a late answer to an earlier request. :class:`LineDiscipline` runs every
transaction of a line (a serial port, or a TCP stream of RTU or FC frames) with the
protocol's framer (:mod:`drive_bridge.protocol.framing`) and takes a frame as the answer to
a request only when it can be nothing else:

- **Before each request** what came since the last transaction is read: anything there came
  late, and the line is quarantined before the request goes out.
- **One frame of the unit per reply window** (:mod:`.reply_window`): frames of other units
  are skipped and counted against the unit they name; a second frame of the unit fails the
  transaction as ambiguous; a frame of the unit that does not answer the request, or that
  was complete before the request and it could have crossed the wire (a real UART only),
  is a late one and fails it.
- **End of frame**: bytes that continue within the inter-frame silence after a frame make
  it one corrupt frame.
- **Quarantine** after a transaction that ended badly (no reply, a corrupt or truncated
  frame, an extra frame): input is read and discarded until the guard after the failed
  window's deadline has passed (the device may still answer until then, however soon the
  window failed) and the line has been silent for the quarantine silence; after one that saw
  a late frame, or before a request when bytes wait, from then on. Every whole frame
  discarded is counted against the unit it names (:attr:`TransactionReport.late`).
- **Owed replies**: a unit whose last window got no whole valid frame of it may still owe
  that reply (a device or gateway that holds it until the next request). Its next
  transaction keeps its first reply window open to the deadline, so that a held reply and
  the answer, arriving one after the other, are two frames and fail it. An acknowledgement
  of a write that would also answer the owed request (the same echo: a drive's next control
  word after a lost one) fails it too, even alone: it cannot be told from the held one.
  Where frames name no unit (AP ASCII) the whole line owes. A frame of the unit seen
  anywhere settles the debt.

The transports (:mod:`.serial_rtu`, :mod:`.ap_ascii`, :mod:`.fc_protocol`) build the request
bytes and say whether a frame answers their request; the :class:`ByteLine` moves bytes.
With a wire trace on (:meth:`LineDiscipline.start_trace`), the line is wrapped so that each
request and each chunk read is noted, and each window and quarantine hands its frames and
their outcomes to the trace (:mod:`.line_trace`); with none, nothing of it runs.
"""

import time
from typing import Any, Callable, Dict, List, Optional, Protocol

from drive_bridge.errors import AmbiguousReply, LineBabble, TransportError
from drive_bridge.protocol.framing import Frame, Framer, frames_in
from drive_bridge.transport.base import LineTiming, TransactionReport
from drive_bridge.transport.line_trace import LineTracer, TracedLine
from drive_bridge.transport.reply_window import Accept, ReplyWindow, Shaped
from drive_bridge.transport.wire_trace import WireTrace

MAX_READ_BYTES = 512  # one read of whatever is there
MAX_SCANNED_BYTES = 4096  # discarded bytes looked through for whole frames, at most
BABBLE_SILENCES = 4  # talking past the guard this many quarantine silences (at least): babble
NO_UNIT = None  # the key of a line whose frames name no unit (it owes as a whole)


class ByteLine(Protocol):
    """What the line discipline needs of a port: bytes in and out, waits bounded."""

    @property
    def is_open(self) -> bool:
        """Return whether the line is open."""

    def connect(self) -> None:
        """Open the line; raise LinkDown with the reason in words."""

    def close(self) -> None:
        """Close the line (idempotent)."""

    def write(self, data: bytes, deadline: float) -> None:
        """Write ``data`` whole by ``deadline``."""

    def read(self, count: int, timeout_s: float, at_least: int = 1) -> bytes:
        """Return up to ``count`` bytes, waiting at most ``timeout_s`` for ``at_least``."""

    def wait_quiet(self, timeout_s: float) -> bytes:
        """Wait ``timeout_s`` (less if bytes arrive) and return what is there, no more."""


class LineDiscipline:
    """Run the transactions of one line; see the module docstring."""

    def __init__(self, line: ByteLine, framer: Framer, timing: LineTiming,
                 clock: Callable[[], float] = time.monotonic,
                 on_request_sent: Callable[[], None] = lambda: None):
        self.line = line
        self.framer = framer
        self.timing = timing
        self.clock = clock
        self.on_request_sent = on_request_sent
        # units that may owe a reply, with what would accept it (see the module docstring)
        self.owed: Dict[Optional[int], Accept] = {}
        self.report = TransactionReport()
        self._unit: Optional[int] = None
        self._first_window = True
        self._window_discards = False  # a window of this transaction discarded something
        self._accept: Optional[Accept] = None  # the last window's: what would answer it
        self._deadline = 0.0  # the last window's deadline
        self._unit_seen = False  # the last window saw a whole valid frame of the unit
        self._answered_badly = False  # the last window: a corrupt answer-shaped frame
        self._owed_before = False  # the unit owed a reply when this transaction began
        self._answer_s = 0.0  # when the last answer of this transaction came
        self.tracer: Optional[LineTracer] = None  # the wire trace's, when one is on

    def start_trace(self, trace: WireTrace) -> None:
        """Trace every request and every frame read from now on (:mod:`.line_trace`)."""
        self.tracer = LineTracer(trace, self.framer, self.clock, self.timing.echo)
        self.line = TracedLine(self.line, self.tracer, self.clock)

    def key(self, unit: Optional[int]) -> Optional[int]:
        """Return the key ``unit`` owes under (the line's, where frames name no unit)."""
        return unit if self.framer.names_units else NO_UNIT

    # -- a transaction ------------------------------------------------------------------
    def begin(self, unit: int) -> None:
        """Start a transaction with ``unit``: anything already there came late."""
        self.report = TransactionReport()
        self._unit, self._first_window, self._accept = unit, True, None
        self._window_discards, self._unit_seen, self._answered_badly = False, False, False
        self._owed_before = self.key(unit) in self.owed
        self._answer_s = self._deadline = 0.0
        pending = self.line.read(MAX_READ_BYTES, 0.0)
        if pending:
            started = self.clock()
            self._discard(pending)
            self.quarantine(started)
            self.report.held_s += self.clock() - started  # not the request's round trip

    def exchange(self, request: bytes, accept: Accept, shaped: Shaped = None,
                 acknowledges: bool = False) -> Any:
        """
        Send ``request`` and return what ``accept`` makes of its answer, or raise.

        ``accept(frame)`` returns the value of a frame of the unit that answers the request,
        or raises BadFrame saying why it does not (a late frame); ``shaped``: see
        :meth:`ReplyWindow.read`. ``acknowledges``: the answer acknowledges a write (the
        request's whole answer, not the first of several fragments): it must not be one that
        would also answer a request the unit still owes. The first exchange of a
        transaction with a unit that owes a reply keeps its window open to the deadline.
        """
        sent_s = self.clock()
        deadline = sent_s + self.timing.timeout_s
        self.line.write(request, deadline)
        self.on_request_sent()
        owed = self.owed.get(self.key(self._unit)) if self._first_window else None
        self._first_window, self._accept, self._deadline = False, accept, deadline
        window = ReplyWindow(self.line, self.framer, self.timing, sent_s, self.clock)
        try:
            if self.timing.echo:
                window.read_echo(request, deadline)
                if self._names_unit(window.late):  # came before the request: the held one
                    owed = None
            value = window.read(self._unit, accept, len(request), deadline, owed, shaped,
                                acknowledges)
        except BaseException as error:
            if self.tracer is not None:
                self.tracer.window(self._unit, error)
            raise
        finally:
            self._take(window)
        if self.tracer is not None:
            self.tracer.window(self._unit, None)
        return value

    def send_only(self, request: bytes) -> None:
        """Send ``request`` that nobody answers (a broadcast); read the adapter's echo."""
        sent_s = self.clock()
        self._first_window, self._deadline = False, sent_s + self.timing.timeout_s
        self.line.write(request, self._deadline)
        self.on_request_sent()
        try:
            if self.timing.echo:
                window = ReplyWindow(self.line, self.framer, self.timing, sent_s, self.clock)
                try:
                    window.read_echo(request, self._deadline)
                finally:
                    self._take(window)
        finally:
            if self.tracer is not None:
                self.tracer.window(self._unit, None, broadcast=True)

    def failed(self, error: TransportError) -> None:
        """
        End a transaction that failed on the line: note what the unit owes, quarantine.

        The quarantine lasts until the guard after the failed window's deadline, however soon
        it failed (garbage, a corrupt or late frame): the device may still send its answer
        until then, and it must not be taken for the next request's. A window that got no
        whole valid frame of the unit leaves the unit owing that answer, unless the unit owed
        nothing before and a corrupt or cut frame of the answer's shape came (it answered;
        the line spoiled it).
        """
        now = self.clock()
        answered = self._unit_seen or (self._answered_badly and not self._owed_before)
        if not answered and self._accept is not None:
            self.owed[self.key(self._unit)] = self._accept
        self.quarantine(max(now, self._deadline), now)

    def done(self) -> None:
        """
        End a transaction that got its answer; quarantine if it saw a late frame.

        A frame of the unit that comes in that quarantine makes the answer ambiguous (it may
        have been a late one after all): AmbiguousReply, and the unit owes its answer.
        """
        if self._window_discards:
            seen = len(self.report.late)
            self.quarantine(self.clock())
            if self._names_unit(self.report.late[seen:]):
                self.owed[self.key(self._unit)] = self._accept
                raise AmbiguousReply('a second frame of the unit came after its answer, in the '
                                     'quarantine: the answer is not provably its own')
        if self._answer_s:
            self.report.after_answer_s = self.clock() - self._answer_s

    # -- quarantine ---------------------------------------------------------------------
    def quarantine(self, since_s: float, last_byte_s: Optional[float] = None) -> None:
        """Quarantine the line (:meth:`_quarantine`); trace what it discarded, if tracing."""
        if self.tracer is None:
            self._quarantine(since_s, last_byte_s)
            return
        try:
            self._quarantine(since_s, last_byte_s)
        except LineBabble:
            self.tracer.discarded('babble')
            raise
        self.tracer.discarded('quarantined')

    def _quarantine(self, since_s: float, last_byte_s: Optional[float] = None) -> None:
        """
        Read and discard input until the guard after ``since_s`` and a silence have passed.

        The silence counts from ``last_byte_s`` (by default ``since_s``), or from the last
        byte read since.

        A line that keeps talking past the guard for longer than the protocol's longest
        frame takes (and four silences) is babbling: LineBabble (another master or a faulty
        device), a link fault.
        """
        timing = self.timing
        guard_end = since_s + timing.guard_s
        silence = timing.quarantine_silence_s
        limit = guard_end + max(self.framer.max_bytes * timing.char_s,
                                BABBLE_SILENCES * silence)
        last_s = since_s if last_byte_s is None else last_byte_s
        discarded = b''
        while True:
            now = self.clock()
            end = max(guard_end, last_s + silence)
            if now >= end:
                break
            if now > limit:
                self._discard(discarded)
                raise LineBabble(f'the line keeps talking ({len(discarded)} bytes past a '
                                 f'failed transaction, no pause of {silence * 1000:.0f} ms '
                                 f'within {limit - since_s:.2g} s): another master or a '
                                 'faulty device is sending')
            chunk = self.line.read(MAX_READ_BYTES, min(end, limit + silence) - now)
            if chunk:
                if len(discarded) < MAX_SCANNED_BYTES:  # a babbler's bytes are only counted
                    discarded += chunk
                else:
                    self.report.noise_bytes += len(chunk)
                last_s = self.clock()
        self._discard(discarded)
        self.report.quiet_s = self.clock() - last_s

    # -- bookkeeping --------------------------------------------------------------------
    def _take(self, window: ReplyWindow) -> None:
        """Take a window's discarded frames and what it saw of the unit into the report."""
        self._unit_seen, self._answered_badly = window.unit_seen, window.answered_badly
        if window.unit_seen:
            self.owed.pop(self.key(self._unit), None)
        self._window_discards = self._window_discards or bool(window.late or window.unread)
        self._count(window.late)
        self.report.noise_bytes += len(window.unread)  # part of a corrupt frame
        self.report.quiet_s = window.quiet_s
        if self._answer_s:  # the earlier window's answer: the time since is not round trip
            self.report.held_s += window.sent_s - self._answer_s
        self._answer_s = window.answer_s

    def _discard(self, data: bytes) -> None:
        """Count the whole frames in discarded bytes as late, the rest as noise."""
        if not data:
            return
        frames, noise = frames_in(self.framer, data)
        self._count(frames)
        self.report.noise_bytes += noise

    def _names_unit(self, frames: List[Frame]) -> bool:
        """Return whether any of ``frames`` may be one of the transaction's unit."""
        key = self.key(self._unit)
        return any(self.key(frame.unit) == key for frame in frames)

    def _count(self, frames: List[Frame]) -> None:
        """
        Count ``frames`` as late; each settles what the unit it names owes.

        A frame that names no unit (AP ASCII: one byte, which noise can make too) settles
        nothing: only a window of the line that gets its reply does.
        """
        for frame in frames:
            self.report.late.append(frame)
            if frame.unit is not None:
                self.owed.pop(frame.unit, None)
