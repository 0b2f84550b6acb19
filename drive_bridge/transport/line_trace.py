"""
The line discipline's side of the wire trace: bytes with their times, frames with outcomes.

Installed only when a trace is on (:meth:`LineDiscipline.start_trace
<drive_bridge.transport.exchange.LineDiscipline.start_trace>`): :class:`TracedLine` wraps the
:class:`~drive_bridge.transport.exchange.ByteLine` and notes each request written and each
chunk read, with the discipline's clock at the moment the read returned it (the read loop's
view: a frame's first and last byte carry the time of the reads that returned them).
:class:`LineTracer` splits what a reply window or a quarantine read into frames as the
protocol's framer does, gives each its outcome and hands them to the
:class:`~drive_bridge.transport.wire_trace.WireTrace`. With the trace off nothing here runs.
"""

import time
from typing import Callable, List, Optional, Tuple

from drive_bridge.errors import MismatchedReply
from drive_bridge.protocol.framing import Framer
from drive_bridge.transport.wire_trace import TraceRecord, WireTrace

Chunk = Tuple[float, bytes]  # (the clock's time the read returned, the bytes)
Span = Tuple[int, int, str, Optional[int]]  # (start, end) in the bytes, outcome, unit


class LineTracer:
    """Turn one line's requests and received chunks into trace records; see the module."""

    def __init__(self, trace: WireTrace, framer: Framer, clock: Callable[[], float],
                 echo: bool = False):
        self.trace = trace
        self.framer = framer
        self.echo = echo
        self._offset_ns = time.time_ns() - int(clock() * 1e9)  # the clock to wall-clock
        self._chunks: List[Chunk] = []
        self._request: Optional[TraceRecord] = None

    def sent(self, data: bytes, start_s: float, end_s: float) -> None:
        """Note a request written between ``start_s`` and ``end_s`` (the clock's times)."""
        self._request = TraceRecord(False, bytes(data), self._ns(start_s), self._ns(end_s))

    def received(self, data: bytes, at_s: float) -> None:
        """Note bytes a read returned at ``at_s``."""
        self._chunks.append((at_s, bytes(data)))

    def window(self, unit: Optional[int], error: Optional[BaseException],
               broadcast: bool = False) -> None:
        """Write the request and the frames its window read, with their outcomes."""
        self._guarded(self._window, unit, error, broadcast)

    def discarded(self, outcome: str = 'quarantined') -> None:
        """Write what a quarantine read: whole frames naming their unit, the rest as runs."""
        self._guarded(self._discarded, outcome)

    def _guarded(self, write: Callable[..., None], *args) -> None:
        """
        Run ``write`` unless the trace is off; a failure stops the trace, never the line.

        It runs where the discipline handles an error of the line: raising here would hide it.
        """
        if not self.trace.enabled:
            self._chunks, self._request = [], None
            return
        try:
            write(*args)
        except Exception as error:  # noqa: B902 - whatever it is, the bus goes on untraced
            self._chunks, self._request = [], None
            self.trace.fail(error)

    def _window(self, unit: Optional[int], error: Optional[BaseException],
                broadcast: bool) -> None:
        outcome = 'broadcast' if broadcast else _kind(error)
        records = []
        request = self._request
        if request is not None:
            records.append(TraceRecord(False, request.data, request.start_ns, request.end_ns,
                                       outcome, unit))
        self._request = None
        data = b''.join(chunk for _, chunk in self._chunks)
        spans = []
        start = 0
        if self.echo and request is not None:
            at = data.find(request.data)
            if at >= 0:
                spans = self._late_frames(data[:at], unit)
                spans.append((at, at + len(request.data), 'echo', None))
                start = at + len(request.data)
        spans += [(begin + start, end + start, kind, named)
                  for begin, end, kind, named in window_spans(self.framer, data[start:], unit,
                                                              error)]
        self._write(records, data, spans)

    def _discarded(self, outcome: str) -> None:
        if not self._chunks:
            return
        data = b''.join(chunk for _, chunk in self._chunks)
        self._write([], data, discarded_spans(self.framer, data, outcome))

    def _late_frames(self, data: bytes, unit: Optional[int]) -> List[Span]:
        """Return the spans of frames ahead of the echo (late ones)."""
        return [(begin, end, 'late' if kind == 'quarantined' else kind, named)
                for begin, end, kind, named in discarded_spans(self.framer, data, 'late')]

    def _write(self, records: List[TraceRecord], data: bytes, spans: List[Span]) -> None:
        """Add a record per span, with the times of its first and last byte, and write."""
        chunks, self._chunks = self._chunks, []
        ends, total = [], 0
        for at_s, chunk in chunks:
            total += len(chunk)
            ends.append((total, at_s))
        for begin, end, outcome, unit in spans:
            records.append(TraceRecord(True, data[begin:end], self._ns(_time_of(ends, begin)),
                                       self._ns(_time_of(ends, end - 1)), outcome, unit))
        self.trace.write(records)

    def _ns(self, clock_s: float) -> int:
        return self._offset_ns + int(clock_s * 1e9)


def _time_of(ends: List[Tuple[int, float]], index: int) -> float:
    """Return the time of the chunk that holds byte ``index``."""
    for end, at_s in ends:
        if index < end:
            return at_s
    return ends[-1][1]


def _kind(error: Optional[BaseException]) -> str:
    """Return the outcome word of a window's error (None: ok)."""
    if error is None:
        return 'ok'
    if isinstance(error, MismatchedReply):
        return 'late'
    return getattr(error, 'kind', 'link')


def window_spans(framer: Framer, data: bytes, unit: Optional[int],
                 error: Optional[BaseException]) -> List[Span]:
    """
    Return the frames of a reply window's bytes and their outcomes.

    A valid frame of another unit: late; of the unit (or of a line whose frames name none):
    the window's outcome (ok, ambiguous, late, nak, ...); a corrupt one: its kind (crc,
    bad_frame); bytes that begin no frame: bad_frame; a frame cut short: truncated.
    """
    spans: List[Span] = []
    position = 0
    outcome = _kind(error)
    while position < len(data):
        cut = framer.cut(data[position:])
        if cut.frame is None:
            spans.append((position, len(data), 'bad_frame' if cut.garbage else 'truncated',
                          None))
            break
        frame = cut.frame
        end = position + len(frame.raw)
        if not frame.valid:
            spans.append((position, end, 'crc' if frame.kind == 'crc' else 'bad_frame',
                          frame.unit))
        elif framer.names_units and frame.unit != unit:
            spans.append((position, end, 'late', frame.unit))
        else:
            spans.append((position, end, _unit_outcome(outcome), frame.unit))
        position = end
    return spans


def _unit_outcome(outcome: str) -> str:
    """Return the outcome of a valid frame of the unit in a window that ended ``outcome``."""
    return 'bad_frame' if outcome in ('timeout', 'truncated', 'wrong_address') else outcome


def discarded_spans(framer: Framer, data: bytes, outcome: str) -> List[Span]:
    """Return the whole valid frames in discarded bytes, and the runs of other bytes."""
    spans: List[Span] = []
    position, noise_from = 0, None
    while position < len(data):
        cut = framer.cut(data[position:])
        if cut.frame is not None and cut.frame.valid:
            if noise_from is not None:
                spans.append((noise_from, position, outcome, None))
                noise_from = None
            end = position + len(cut.frame.raw)
            spans.append((position, end, outcome, cut.frame.unit))
            position = end
            continue
        if noise_from is None:
            noise_from = position
        position += 1
    if noise_from is not None:
        spans.append((noise_from, len(data), outcome, None))
    return spans


class TracedLine:
    """A :class:`ByteLine` that tells a :class:`LineTracer` what it moves."""

    def __init__(self, line, tracer: LineTracer, clock: Callable[[], float]):
        self.inner = line
        self.tracer = tracer
        self.clock = clock

    @property
    def is_open(self) -> bool:
        """Return whether the line is open."""
        return self.inner.is_open

    def connect(self) -> None:
        """Open the line."""
        self.inner.connect()

    def close(self) -> None:
        """Close the line."""
        self.inner.close()

    def write(self, data: bytes, deadline: float) -> None:
        """Write ``data`` and note it with the times around the write."""
        start_s = self.clock()
        self.inner.write(data, deadline)
        self.tracer.sent(data, start_s, self.clock())

    def read(self, count: int, timeout_s: float, at_least: int = 1) -> bytes:
        """Read as the line does and note what came."""
        data = self.inner.read(count, timeout_s, at_least)
        if data:
            self.tracer.received(data, self.clock())
        return data

    def wait_quiet(self, timeout_s: float) -> bytes:
        """Wait as the line does and note what came."""
        data = self.inner.wait_quiet(timeout_s)
        if data:
            self.tracer.received(data, self.clock())
        return data
