"""
A wire pacer: a 2-wire RS-485 line between a master's serial port and a simulator's pty.

A pty moves bytes at once and nothing on it checks the Modbus RTU 3.5-character silence, so a
master talking to a simulator over one is as fast as the CPU allows. The pacer sits between
them: it opens the simulator's port as its upstream (the slave side) and offers a pty of its
own, optionally behind a symlink, to the master. Bytes cross it as they would cross a line at
the given baud rate, parity and stop bits:

- every byte takes its wire time (start, 8 data, parity and stop bits) and is handed on once
  its last bit has crossed; what a side writes while its earlier bytes are still on the wire
  queues behind them, as in a UART;
- the line is half duplex: bytes of the two sides that overlap in time collide, and both
  frames are garbled (their receivers get nothing of them from the collision on);
- with the gap rule (Modbus RTU) every frame must follow 3.5 characters of silence on the
  wire, whoever sends it. A frame that starts sooner is glued to the previous one and not
  recognised (dropped, and the previous frame too if its receiver has not taken it yet); a
  silence of more than 1.5 characters inside a frame breaks it. The slave side is handed a
  frame once 3.5 characters of silence have followed it, as an RTU slave recognises one, so a
  simulator that answers at once still keeps the gap; the master side gets bytes as they
  leave the wire, as from a UART, and reads by length. A master that breaks the gap loses
  the transaction; it never gains time.
- ``ideal_slave`` (the benches): the slave gets bytes as they leave the wire, as the master
  does (the simulator frames requests by length), and a reply it writes goes on the wire
  exactly 3.5 characters after the request, however soon it was written: a slave with no
  processing time of its own (as long as it answers within the gap), which is what the wire
  limit assumes, so that a bench measures the master and not the simulator's process. The
  master is held to the gap as before.

Without the gap rule (AP ASCII, the FC protocol: byte streams) both sides get bytes as they
leave the wire. The pacer keeps a bounded log of the frames on the wire (sender, start and end
on the wire in the clock's seconds, bytes, fate) and counters. :class:`WireLine` is the pure
timing model (it is told the time); :class:`WirePacer` runs one on a thread between two file
descriptors. Standard library only.
"""

from collections import deque
from dataclasses import dataclass, field, replace
import os
import select
import threading
import time
import tty
from typing import Callable, Deque, Dict, List, Optional, Sequence, Tuple

from drive_bridge.protocol import rtu
from drive_bridge.sim.pty_link import PtyLink

MASTER = 'master'
SLAVE = 'slave'
SENDERS = (MASTER, SLAVE)
_OTHER = {MASTER: SLAVE, SLAVE: MASTER}

OK = 'ok'
GAP_VIOLATION = 'gap_violation'  # started too soon after the previous frame, or broken inside
GLUED = 'glued'  # a frame the next one was glued to before its receiver had taken it
COLLISION = 'collision'  # overlapped a frame of the other side

MAX_INNER_GAP_CHARS = 1.5  # Modbus RTU: a longer silence inside a frame breaks it
MAX_INNER_GAP_FAST_S = 0.00075  # the fixed t1.5 above 19200 baud
DEFAULT_LOG_SIZE = 10000
MAX_FRAME_BYTES = 4096  # a longer burst without a silence goes on as a new frame in the log
MODBUS_GAP_CHARACTERS = 3.5
ROUNDING_S = 1e-9  # byte times add up one by one: a silence this much short still counts


@dataclass(frozen=True)
class LineTiming:
    """The character timing of the line and whether the Modbus RTU gap rule applies."""

    baudrate: int
    parity: str = 'E'
    stopbits: int = 1
    gap_rule: bool = True
    gap_characters: float = MODBUS_GAP_CHARACTERS  # silence before a frame; FC protocol: 2

    def __post_init__(self):
        if self.baudrate <= 0:
            raise ValueError(f'baud rate must be positive, not {self.baudrate}')
        if self.parity not in ('N', 'E', 'O'):
            raise ValueError(f'parity must be N, E or O, not {self.parity!r}')
        if self.stopbits not in (1, 2):
            raise ValueError(f'stop bits must be 1 or 2, not {self.stopbits}')

    @property
    def char_s(self) -> float:
        """Return the wire time of one character (11 bits for 8E1 and 8N2, 10 for 8N1)."""
        return rtu.character_time_s(self.baudrate, self.parity, self.stopbits)

    @property
    def gap_s(self) -> float:
        """Return the silence before a frame: Modbus 3.5 characters (1.75 ms above 19200)."""
        if self.gap_characters == MODBUS_GAP_CHARACTERS:
            return rtu.frame_gap_s(self.baudrate, self.parity, self.stopbits)
        return self.gap_characters * self.char_s

    @property
    def inner_gap_s(self) -> float:
        """Return the longest silence allowed inside a frame (1.5 characters)."""
        if self.baudrate > 19200:
            return MAX_INNER_GAP_FAST_S
        return MAX_INNER_GAP_CHARS * self.char_s

    def transaction_s(self, request_bytes: int, reply_bytes: int) -> float:
        """Return the least time a request and its reply occupy the line, both gaps included."""
        return (request_bytes + reply_bytes) * self.char_s + 2 * self.gap_s

    def describe(self) -> str:
        """Return the timing in words, e.g. ``19200 baud 8E1 (11 bits), gap rule on``."""
        bits = rtu.character_bits(self.parity, self.stopbits)
        rule = 'on' if self.gap_rule else 'off'
        return f'{self.baudrate} baud 8{self.parity}{self.stopbits} ({bits} bits), gap rule {rule}'


@dataclass(frozen=True)
class WireFrame:
    """One frame as it crossed the wire: sender, start and end (clock seconds), bytes, fate."""

    sender: str
    start_s: float
    end_s: float
    data: bytes
    fate: str = OK

    @property
    def receiver(self) -> str:
        """Return the side the frame was for."""
        return _OTHER[self.sender]


@dataclass
class LineCounters:
    """What crossed the line: frames and bytes per sender, and what went wrong."""

    frames: Dict[str, int] = field(default_factory=lambda: dict.fromkeys(SENDERS, 0))
    bytes_sent: Dict[str, int] = field(default_factory=lambda: dict.fromkeys(SENDERS, 0))
    gap_violations: int = 0
    collisions: int = 0
    lost_frames: int = 0  # frames garbled by a gap violation, gluing or a collision

    def copy(self) -> 'LineCounters':
        """Return an independent copy."""
        return replace(self, frames=dict(self.frames), bytes_sent=dict(self.bytes_sent))


class _Frame:
    """A frame being sent or handed on: its bytes, when each one ends, how far it is taken."""

    __slots__ = ('sender', 'start_s', 'end_s', 'data', 'byte_ends', 'fate', 'garbled_at_s',
                 'taken', 'collided_with')

    def __init__(self, sender: str, start_s: float):
        self.sender = sender
        self.start_s = start_s
        self.end_s = start_s
        self.data = bytearray()
        self.byte_ends: List[float] = []
        self.fate = OK
        self.garbled_at_s: Optional[float] = None
        self.taken = 0  # bytes handed on or dropped
        self.collided_with: Optional['_Frame'] = None

    @property
    def receiver(self) -> str:
        return _OTHER[self.sender]

    def add(self, byte: int, end_s: float) -> None:
        self.data.append(byte)
        self.byte_ends.append(end_s)
        self.end_s = end_s

    def garble(self, at_s: float, fate: str) -> bool:
        """Garble the bytes that end after ``at_s``; return whether the frame was whole."""
        was_whole = self.garbled_at_s is None
        if was_whole or at_s < self.garbled_at_s:
            self.garbled_at_s = at_s
        if was_whole:
            self.fate = fate
        return was_whole

    def take_bytes(self, now_s: float) -> bytes:
        """Return the whole bytes that have left the wire by ``now_s`` and not been taken."""
        data = bytearray()
        while self.taken < len(self.data) and self.byte_ends[self.taken] <= now_s:
            end_s = self.byte_ends[self.taken]
            if self.garbled_at_s is None or end_s <= self.garbled_at_s:
                data.append(self.data[self.taken])
            self.taken += 1
        return bytes(data)

    def record(self) -> WireFrame:
        return WireFrame(self.sender, self.start_s, self.end_s, bytes(self.data), self.fate)


class WireLine:
    """
    The pure timing model of a half-duplex line between a master and a slave.

    :meth:`transmit` puts bytes a side wrote on the wire; :meth:`take_due` returns what each
    side receives by a given time; :meth:`next_due_s` tells when to ask next. Times are
    seconds of one monotonic clock, passed in; nothing here reads a clock or sleeps.
    """

    def __init__(self, timing: LineTiming, log_size: int = DEFAULT_LOG_SIZE,
                 ideal_slave: bool = False):
        self.timing = timing
        self.counters = LineCounters()
        self._log: Deque[_Frame] = deque(maxlen=log_size)
        self._current: Dict[str, Optional[_Frame]] = dict.fromkeys(SENDERS)
        self._latest: Optional[_Frame] = None  # the frame that started last on the wire
        self._pending: Dict[str, Deque[_Frame]] = {side: deque() for side in SENDERS}
        # With the gap rule the slave is an RTU slave: it takes a frame after the silence.
        # An ideal slave instead gets bytes as they leave the wire (it frames by length) and
        # its reply goes on the wire exactly when the gap allows, however soon it is written.
        ideal = ideal_slave and timing.gap_rule
        self._frame_receivers = {SLAVE} if timing.gap_rule and not ideal else set()
        self._gap_keepers = {SLAVE} if ideal else set()

    # -- sending ------------------------------------------------------------------------
    def transmit(self, sender: str, data: bytes, now_s: float) -> None:
        """Put ``data``, written by ``sender`` at ``now_s``, on the wire behind its queue."""
        if sender not in SENDERS:
            raise ValueError(f'sender must be {MASTER} or {SLAVE}, not {sender!r}')
        char_s = self.timing.char_s
        now_s = self._held_for_gap(sender, now_s)
        for byte in data:
            current = self._current[sender]
            start_s = now_s if current is None else max(now_s, current.end_s)
            frame = self._frame_for(sender, start_s)
            frame.add(byte, start_s + char_s)
            self._check_collision(frame, start_s, start_s + char_s)
        self.counters.bytes_sent[sender] += len(data)

    def _held_for_gap(self, sender: str, now_s: float) -> float:
        """Return when an ideal slave's bytes written at ``now_s`` may go on the wire."""
        latest = self._latest
        if sender not in self._gap_keepers or latest is None:
            return now_s
        if latest is self._current[sender] and now_s <= latest.end_s + self.timing.inner_gap_s:
            return now_s  # more of the frame it is sending
        return max(now_s, latest.end_s + self.timing.gap_s)

    def _frame_for(self, sender: str, start_s: float) -> _Frame:
        """Return the frame a byte of ``sender`` starting at ``start_s`` belongs to."""
        frame = self._current[sender]
        if frame is not None and len(frame.data) < MAX_FRAME_BYTES:
            silence_s = start_s - frame.end_s
            if silence_s <= 0 or (frame is self._latest and silence_s < self.timing.gap_s):
                if self.timing.gap_rule and silence_s > self.timing.inner_gap_s:
                    self._garble(frame, frame.start_s, GAP_VIOLATION)
                return frame
        return self._new_frame(sender, start_s)

    def _new_frame(self, sender: str, start_s: float) -> _Frame:
        previous = self._previous_frame(start_s)
        frame = _Frame(sender, start_s)
        self._current[sender] = frame
        self._latest = frame
        self._log.append(frame)
        self._pending[frame.receiver].append(frame)
        self.counters.frames[sender] += 1
        if self.timing.gap_rule and previous is not None and \
                start_s - previous.end_s < self.timing.gap_s - ROUNDING_S:
            self._garble(frame, start_s, GAP_VIOLATION)
            if previous.receiver in self._frame_receivers:  # not taken yet: lost with it
                self._garble(previous, previous.start_s, GLUED)
        return frame

    def _previous_frame(self, start_s: float) -> Optional[_Frame]:
        """Return the frame that ended last before ``start_s``; None if one is still on."""
        frames = [frame for frame in self._current.values() if frame is not None]
        if any(frame.end_s > start_s for frame in frames):
            return None  # the line is busy: a collision, not a gap
        return max(frames, key=lambda frame: frame.end_s, default=None)

    def _check_collision(self, frame: _Frame, start_s: float, end_s: float) -> None:
        other = self._current[_OTHER[frame.sender]]
        if other is None or not (start_s < other.end_s and other.start_s < end_s):
            return
        if frame.collided_with is not other:
            self.counters.collisions += 1
            frame.collided_with, other.collided_with = other, frame
        at_s = max(start_s, other.start_s)
        self._garble(frame, at_s, COLLISION)
        self._garble(other, at_s, COLLISION)

    def _garble(self, frame: _Frame, at_s: float, fate: str) -> None:
        if frame.garble(at_s, fate):
            self.counters.lost_frames += 1
            if fate == GAP_VIOLATION:
                self.counters.gap_violations += 1

    # -- receiving ----------------------------------------------------------------------
    def take_due(self, now_s: float) -> List[Tuple[str, bytes]]:
        """Return (receiver, bytes) for every side that has received something by ``now_s``."""
        received = []
        for receiver, pending in self._pending.items():
            data = bytearray()
            while pending:
                frame = pending[0]
                if receiver in self._frame_receivers:
                    if now_s < frame.end_s + self.timing.gap_s:
                        break
                    if frame.garbled_at_s is None:
                        data += frame.data
                    frame.taken = len(frame.data)
                else:
                    data += frame.take_bytes(now_s)
                    if frame.taken < len(frame.data) or self._may_continue(frame, now_s):
                        break
                pending.popleft()
                frame.byte_ends = []
            if data:
                received.append((receiver, bytes(data)))
        return received

    def _may_continue(self, frame: _Frame, now_s: float) -> bool:
        """Return whether bytes written from ``now_s`` on could still join ``frame``."""
        return frame is self._current[frame.sender] and now_s < frame.end_s + self.timing.gap_s

    def next_due_s(self, batch_s: float = 0.0) -> Optional[float]:
        """
        Return when a receiver next has something to take, or None.

        ``batch_s`` > 0 hands on the bytes of a frame in batches of that length, as a USB
        adapter does, except the last byte written so far, which is never held back.
        """
        due = []
        for receiver, pending in self._pending.items():
            if not pending:
                continue
            frame = pending[0]
            if receiver in self._frame_receivers:
                due.append(frame.end_s + self.timing.gap_s)
            elif frame.taken < len(frame.data):
                due.append(min(frame.byte_ends[-1], frame.byte_ends[frame.taken] + batch_s))
        return min(due, default=None)

    # -- log ----------------------------------------------------------------------------
    def frames(self) -> List[WireFrame]:
        """Return the logged frames, oldest first (the newest ``log_size`` only)."""
        return [frame.record() for frame in self._log]


def transactions(frames: Sequence[WireFrame]) -> List[Tuple[WireFrame, WireFrame]]:
    """Return (request, reply) pairs: a whole master frame followed by a whole slave frame."""
    return [(request, reply) for request, reply in zip(frames, frames[1:])
            if request.sender == MASTER and reply.sender == SLAVE and
            request.fate == OK and reply.fate == OK]


def wire_fraction(pairs: Sequence[Tuple[WireFrame, WireFrame]], timing: LineTiming,
                  seconds: float) -> float:
    """
    Return the share of ``seconds`` that ``pairs`` need at the least, gaps included.

    1.0 is the wire limit: transactions per second / (1 / the mean transaction wire time).
    """
    busy_s = sum(timing.transaction_s(len(request.data), len(reply.data))
                 for request, reply in pairs)
    return busy_s / seconds


class WirePacer:
    """
    Run a :class:`WireLine` on a thread between a master's pty and a simulator's port.

    ``open_pty`` on the simulator's port (a pty slave path), give the returned path to the master,
    then ``start``. ``frames()`` and ``counters()`` may be read from any thread.
    """

    def __init__(self, timing: LineTiming, log_size: int = DEFAULT_LOG_SIZE,
                 batch_s: float = 0.002, clock: Callable[[], float] = time.monotonic,
                 ideal_slave: bool = False):
        self.timing = timing
        self.batch_s = batch_s
        self.clock = clock
        self.path = ''
        self.overflow_bytes = 0  # bytes a side's pty would not take (its buffer was full)
        self.lost_sides: List[str] = []  # sides whose port closed under the pacer
        self._line = WireLine(timing, log_size, ideal_slave)
        self._lock = threading.Lock()
        self._fds: Dict[str, int] = {}
        self._pty: Optional[PtyLink] = None
        self._wake_r, self._wake_w = os.pipe()
        self._thread: Optional[threading.Thread] = None
        self._running = False

    def open_pty(self, upstream_path: str, link_path: str = '') -> str:
        """Open ``upstream_path`` (the simulator) and a pty for the master; return its path."""
        upstream = os.open(upstream_path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        if os.isatty(upstream):
            tty.setraw(upstream)
        self._pty = PtyLink(link_path)
        self._fds = {MASTER: self._pty.master, SLAVE: upstream}
        self.path = self._pty.path
        return self.path

    def start(self) -> 'WirePacer':
        """Pace on a background thread."""
        if not self._fds:
            raise RuntimeError('open_pty() the pacer before start()')
        self._running = True
        self._thread = threading.Thread(target=self._run, name='wire-pacer', daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop pacing and close both ports, the master's symlink and the thread (idempotent)."""
        self._running = False
        if self._thread is not None:
            os.write(self._wake_w, b'x')
            self._thread.join(timeout=5)
            self._thread = None
        if SLAVE in self._fds:
            os.close(self._fds.pop(SLAVE))
        if self._pty is not None:
            self._pty.close()
            self._pty = None
        self._fds.clear()
        for fd in (self._wake_r, self._wake_w):
            try:
                os.close(fd)
            except OSError:
                pass

    def frames(self) -> List[WireFrame]:
        """Return the frame log, oldest first."""
        with self._lock:
            return self._line.frames()

    def counters(self) -> LineCounters:
        """Return a copy of the counters."""
        with self._lock:
            return self._line.counters.copy()

    # -- thread -------------------------------------------------------------------------
    def _run(self) -> None:
        watched = [self._wake_r, *self._fds.values()]
        side_of = {fd: side for side, fd in self._fds.items()}
        while self._running:
            with self._lock:
                due_s = self._line.next_due_s(self.batch_s)
            timeout_s = 0.5 if due_s is None else min(0.5, max(0.0, due_s - self.clock()))
            # select.select takes microseconds; epoll and poll round timeouts up to 1 ms.
            readable, _, _ = select.select(watched, [], [], timeout_s)
            now_s = self.clock()
            for fd in readable:
                if fd == self._wake_r:
                    os.read(fd, 64)
                    continue
                data = self._read(fd, side_of[fd], watched)
                if data:
                    with self._lock:
                        self._line.transmit(side_of[fd], data, now_s)
            with self._lock:
                received = self._line.take_due(self.clock())
            for side, data in received:
                self._write(self._fds[side], data)

    def _read(self, fd: int, side: str, watched: List[int]) -> bytes:
        try:
            data = os.read(fd, 4096)
        except BlockingIOError:
            return b''
        except OSError:
            data = b''
        if not data:  # the other end closed (a simulator stopped): stop watching it
            watched.remove(fd)
            self.lost_sides.append(side)
        return data

    def _write(self, fd: int, data: bytes) -> None:
        try:
            written = os.write(fd, data)
        except BlockingIOError:
            written = 0
        except OSError:
            return
        self.overflow_bytes += len(data) - written
