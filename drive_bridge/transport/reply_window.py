"""
One reply window: the frames that arrive after a request, until the answer or the deadline.

:class:`ReplyWindow` reads the frames of one window with the protocol's framer and decides,
for the line discipline (:mod:`.exchange`), which one is the answer:

- a frame of another unit is skipped and kept as a late reply (:attr:`ReplyWindow.late`);
- the first frame of the unit is the answer if ``accept`` takes it, it was not complete
  before the request and it could have crossed the wire (a paced line only: a real UART),
  and the line then stays silent for the inter-frame gap (end of frame: bytes within the
  gap make it one corrupt frame). Otherwise it is a late frame and the transaction fails;
- a window held open (a unit that owes an earlier reply) reads on to the deadline: a
  second frame of the unit fails the transaction as ambiguous, whichever came first, and so
  does a single acknowledgement of a write that would also acknowledge the owed request;
- a corrupt frame or bytes that begin no frame fail it at once; the quarantine that follows
  reads the rest.

Every wait ends at the transaction's deadline; nothing here sleeps beyond it but the one
inter-frame gap after the answer.
"""

import time
from typing import Any, Callable, List, Optional

from drive_bridge.errors import (
    AmbiguousReply, BadFrame, CrcError, MismatchedReply, NoResponse, TruncatedFrame,
    WrongAddress)
from drive_bridge.protocol.framing import Frame, Framer
from drive_bridge.transport.base import LineTiming

# A reply complete sooner than this share of its wire time (and the request's) is not ours:
# UART clocks are within a few percent of each other, and USB adapters only delay bytes.
EARLY_TOLERANCE = 0.1
Accept = Callable[[Frame], Any]  # the value of a frame that answers, or raise BadFrame
Shaped = Optional[Callable[[Frame], bool]]  # a corrupt frame has the answer's shape
_NOTHING = object()


class ReplyWindow:
    """Read one reply window; see the module docstring."""

    def __init__(self, line, framer: Framer, timing: LineTiming, sent_s: float,
                 clock: Callable[[], float] = time.monotonic):
        self.line = line
        self.sent_s = sent_s  # when the request of this window went out (the clock's time)
        self.framer = framer
        self.timing = timing
        self.clock = clock
        self.late: List[Frame] = []  # whole frames that were not the answer
        self.unread = b''  # bytes read and not taken (the quarantine counts them)
        self.unit_seen = False  # a whole valid frame of the unit came
        self.answered_badly = False  # a corrupt or cut frame that shows the answer's unit came
        self.quiet_s = 0.0  # the silence kept after the last byte before returning
        self.answer_s = 0.0  # when the last byte of the answer came (the clock's time)
        self._last_byte_s = 0.0
        self._shaped: Shaped = None

    def read_echo(self, request: bytes, deadline: float) -> None:
        """
        Read the adapter's echo of ``request`` (``local_echo``).

        Whole frames ahead of it (a late reply that was on the line first) are late; any
        other bytes mean the adapter did not echo: BadFrame.
        """
        buffer = b''
        while buffer != request:
            wanted = len(request)
            if buffer and not request.startswith(buffer):
                cut = self.framer.cut(buffer)
                if cut.frame is not None and cut.frame.valid:
                    self.late.append(cut.frame)
                    buffer = buffer[len(cut.frame.raw):]
                    continue
                if cut.frame is not None or cut.garbage:
                    self.unread = buffer
                    raise BadFrame('the adapter did not echo the request (local_echo is '
                                   f'set): {_shown(buffer)}')
                wanted = max(cut.needed, len(request))
            missing = wanted - len(buffer)
            chunk = self.line.read(missing, deadline - self.clock(), at_least=missing)
            buffer += chunk
            if len(chunk) < missing:
                self.unread = buffer
                raise BadFrame('the adapter did not echo the request (local_echo is set): '
                               f'{len(buffer)} of {len(request)} bytes came back')

    def read(self, unit: Optional[int], accept: Accept, request_bytes: int, deadline: float,
             owed: Optional[Accept] = None, shaped: Shaped = None,
             acknowledges: bool = False) -> Any:
        """
        Return the value of the answer of ``unit`` (see the module docstring), or raise.

        ``owed``: what would accept the answer to an earlier request of the unit that got
        none: the window is then held open to its deadline; and when the answer
        ``acknowledges`` a write, a frame that ``owed`` accepts too is no acknowledgement
        (it may be the held one: an ambiguous acknowledgement counts as none).

        ``shaped(frame)``: whether a corrupt frame, or one cut short, has the answer's shape
        (its unit and function), so that its checksum error or its end is the answer's
        (CrcError, TruncatedFrame: noise on the line) rather than garbage (BadFrame); None:
        any such frame is as its framer says.
        """
        sent_s = self.sent_s
        self._shaped = shaped
        buffer, answer, first, others, time_up = b'', _NOTHING, None, 0, False
        while True:
            cut = self.framer.cut(buffer)
            if cut.frame is None:
                if cut.garbage:
                    self.unread = buffer
                    raise BadFrame(f'invalid reply ({_shown(buffer)}), {len(buffer)} bytes '
                                   'received')
                if time_up:
                    return self._window_ended(unit, buffer, answer, others)
                missing = cut.needed - len(buffer)
                chunk = self.line.read(missing, deadline - self.clock(), at_least=missing)
                if chunk:
                    buffer += chunk
                    self._last_byte_s = self.clock()
                time_up = len(chunk) < missing and self.clock() >= deadline
                continue
            frame, buffer = cut.frame, buffer[len(cut.frame.raw):]  # reads take no more
            self._check_valid(frame)
            if self.framer.names_units and frame.unit != unit:
                self.late.append(frame)
                others += 1
                continue
            if answer is not _NOTHING:
                self.late.extend((first, frame))
                raise AmbiguousReply(f'two frames in one reply window, the second '
                                     f'{frame.describe()}: neither is provably the answer (a '
                                     'late reply came with it)')
            value = self._answer(frame, accept, sent_s, request_bytes,
                                 owed if acknowledges else None)
            self.answer_s = self._last_byte_s
            value = self._end_of_frame(frame, value)
            if owed is None:
                return value
            answer, first = value, frame  # held open: read on to the deadline

    # -- the frames -----------------------------------------------------------------------
    def _check_valid(self, frame: Frame) -> None:
        """Raise unless ``frame`` is whole and valid (a checksum error, or garbage)."""
        if not frame.valid:
            self.unread = frame.raw
            answer_like = self._shaped is None or self._shaped(frame)
            self.answered_badly = self._shows_answer(frame)
            error_type = CrcError if frame.kind == 'crc' and answer_like else BadFrame
            raise error_type(f'invalid reply ({frame.error}), {len(frame.raw)} bytes received')

    def _shows_answer(self, frame: Frame) -> bool:
        """
        Return whether a corrupt or cut frame shows the unit and kind of the answer.

        Only then does it tell that the unit answered (noise spoiled it): a stray byte, or a
        frame of a protocol whose frames name no unit, tells nothing of whose it is.
        """
        return self.framer.names_units and self._shaped is not None and \
            len(frame.raw) >= self.framer.header_bytes and self._shaped(frame)

    def _answer(self, frame: Frame, accept: Accept, sent_s: float, request_bytes: int,
                owed: Optional[Accept]) -> Any:
        """Return the value of the unit's ``frame``, or raise: it is a late one."""
        self.unit_seen = True
        if owed is not None and _accepts(owed, frame):
            self.late.append(frame)
            raise AmbiguousReply(f'{frame.describe()} would also acknowledge an earlier '
                                 'request that got no reply: it cannot be told from a held one')
        if self._too_early(frame, sent_s, request_bytes):
            self.late.append(frame)
            raise MismatchedReply(f'{frame.describe()} was whole before the request and a '
                                  'reply could have crossed the wire: a late reply')
        try:
            return accept(frame)
        except BadFrame as error:
            self.late.append(frame)
            raise MismatchedReply(f'{error}: not the answer to this request (a late '
                                  'reply?)') from None

    def _too_early(self, frame: Frame, sent_s: float, request_bytes: int) -> bool:
        """Return whether a paced line delivered ``frame`` too soon to answer the request."""
        if not self.timing.paced:
            return False
        wire_s = (request_bytes + len(frame.raw)) * self.timing.char_s
        return self._last_byte_s - sent_s < wire_s * (1.0 - EARLY_TOLERANCE)

    def _end_of_frame(self, frame: Frame, value: Any) -> Any:
        """Return ``value`` once the line kept the gap after ``frame``; else raise."""
        extra = self.line.wait_quiet(self.timing.gap_s)
        if extra:
            self.unread = frame.raw + extra
            raise BadFrame(f'invalid reply ({len(extra)} bytes continue the reply within the '
                           'inter-frame silence: one corrupt frame)')
        self.quiet_s = self.clock() - self._last_byte_s
        return value

    def _window_ended(self, unit: Optional[int], buffer: bytes, answer: Any, others: int) -> Any:
        """Return the answer of a window that ran to its deadline, or raise why none."""
        if buffer:
            self.unread = buffer
            if self._shaped is not None and not self._shaped(Frame(bytes(buffer))):
                raise BadFrame(f'invalid reply ({_shown(buffer)}: cut short, and not the unit '
                               f'and function of the answer), {len(buffer)} bytes received')
            needed = self.framer.cut(buffer).needed
            self.answered_badly = self._shows_answer(Frame(bytes(buffer)))
            raise TruncatedFrame(f'truncated reply: {_part(buffer, needed)} within '
                                 f'{self.timing.timeout_s:g} s')
        if answer is not _NOTHING:
            self.quiet_s = self.clock() - self._last_byte_s
            return answer
        if others:
            raise WrongAddress(f'no reply from address {unit} within '
                               f'{self.timing.timeout_s:g} s; {others} '
                               f'frame{"s" * (others > 1)} of other units came instead')
        raise NoResponse(f'no reply within {self.timing.timeout_s:g} s')


def _accepts(accept: Accept, frame: Frame) -> bool:
    """Return whether ``accept`` takes ``frame`` as an answer (it raises BadFrame if not)."""
    try:
        accept(frame)
    except BadFrame:
        return False
    return True


def _shown(data: bytes) -> str:
    """Return the first bytes of ``data`` in hex, for messages."""
    text = data[:16].hex(' ')
    return text + (' ...' if len(data) > 16 else '')


def _part(buffer: bytes, needed: int) -> str:
    if needed > len(buffer):
        return f'{len(buffer)} of {needed} bytes'
    return f'{len(buffer)} byte{"s" * (len(buffer) > 1)}, too few to tell its length,'
