"""
The soak's oracle: the bridge's safety invariants checked from the outside.

Two records and nothing else: what each simulated device received and executed, in line
order (:class:`~soak_harness.line.WireFrame`), and the client's own record of what
it asked and what it was told (:class:`ClientLog`: commands and their answers, speed
references, and what the bridge reported about a device: offline, online, tripped). Nothing
of the bridge's own state is read. Every record carries the *line sequence* at the moment it
happened (how many requests the line had carried), so the two records fall into one order.

The invariants (the manual's safety model, docs/safety.md):

1. Nothing that could start a motor reaches a device unless a start the client asked for is
   in force. Every start or run write a device executed is explained by a start the client
   asked for that was acknowledged or whose outcome was not yet reported. Its own write goes
   out once, and not after a stop asked later had been carried out, nor after the device
   went offline or reported a trip. A drive's control word or the gateway's Fwd Run image
   is rewritten (keepalive) only while that start is in force: not after a stop, quick stop,
   coast stop or reset was asked for (whatever its outcome), after the client was told the
   start failed, after a newer start that was sent failed, after the device reported a trip,
   after it went offline (and came back), or after the shutdown's stops; one that went
   offline holding a run gets a stop word once it answers again (``no_stop_after_outage``).
   A request the simulator took from a backlog (``WireFrame.late``: its thread was held up)
   is not judged by these timing rules; the others still apply to it (a late reference need
   only be one the client set before it).
2. A start answered as failed never reaches the wire after the failure was reported, and
   went out at most once (kinds ``run_after_failed_start``, ``start_twice``).
3. Every acknowledged command reached the device: the device executed its write(s), and
   the reply that acknowledged it was not spoiled.
4. Every reference word a drive executed is one the client set (or the configured one), and
   a reference outside [-200, 200) % or not finite never reaches the wire.
5. A monitor-only device receives no write at all.
6. After the shutdown every motor of a device with ``stop_on_shutdown`` is stopped (read
   from the simulated device); a device without it gets no write after the shutdown.

Timing: in an *exact* record the client's calls and the bus's answers happen between two
transactions of the line (the bus runs in the client's thread), so a command's own writes
are the line's last requests when its answer comes. Otherwise (the node: answers travel
through ROS) an answer is placed when the client received it, and a command's writes lie
between its asking and its answer; a stop then ends a run only from its answer on, and an
answer or a notice takes effect one request late (the request the master may have given up
on can still wait in the simulator). Both are sound: a correct bridge gives no violation.
"""

from collections import Counter, defaultdict
from dataclasses import dataclass, field
import math
import struct
import threading
import time
from typing import Callable, Dict, Iterable, List, Optional, Sequence, Tuple

from drive_bridge.errors import CommandRefused
from drive_bridge.protocol import fc_profile_scaling
from soak_harness.line import WireFrame

ACKNOWLEDGED = 'acknowledged'
UNACKNOWLEDGED = 'unacknowledged'  # sent; no valid acknowledgement: it may have run
REJECTED = 'rejected'  # the device answered with an exception: not executed
NOT_SENT = 'not sent'  # refused before sending, expired, dropped
OUTCOMES = (ACKNOWLEDGED, UNACKNOWLEDGED, REJECTED, NOT_SENT)
MAY_HAVE_RUN = (ACKNOWLEDGED, UNACKNOWLEDGED, '')  # '' = never answered
STOP_CLASS = ('stop', 'quick_stop', 'coast_stop', 'reset', 'forced_comms_trip')
# After an outage the stop image goes out with the first poll (the probe); a few polls' worth
# of requests leave room for a spoiled keepalive write.
STOP_AFTER_OUTAGE_FRAMES = 12
# The writes that carry out each command, in order; each entry is the set of labels the
# write may carry (soak_line.ControlWrite.label). From the manuals: MCD register 40002 (one
# write); the FC profile (a reset is the reset bit, then a ramp stop); the gateway image
# (quick stop: Quick Stop set before Fwd Run is cleared; reset: a pulse on bit 3).
EXPECTED_WRITES: Dict[str, Dict[str, Tuple[Tuple[str, ...], ...]]] = {
    'mcd': {'start': (('start',),), 'stop': (('stop',),), 'quick_stop': (('quick_stop',),),
            'reset': (('reset',),), 'forced_comms_trip': (('forced_comms_trip',),)},
    'drive': {'start': (('start',),), 'stop': (('stop',),), 'quick_stop': (('quick_stop',),),
              'coast_stop': (('coast_stop',),), 'reset': (('reset',), ('stop',))},
    'lvsg': {'start': (('start',),), 'stop': (('stop',),),
             'quick_stop': (('quick_stop_hold', 'quick_stop'), ('quick_stop',)),
             'reset': (('reset',), ('stop', 'quick_stop'))},
}
VIOLATION_KINDS: Dict[str, str] = {
    'run_without_start': 'a start or run write that no start the client asked for explains',
    'run_after_end': 'a run image written after its start had ended (stop asked, newer '
                     'start failed, offline, trip, shutdown)',
    'run_after_failed_start': 'a start on the wire after the client was told it failed',
    'no_stop_after_outage': 'a drive or gateway that went offline holding a run got no stop '
                            'word once it answered again',
    'start_twice': 'one start request executed more than once',
    'start_after_stop': 'a start written after a stop asked later had been carried out',
    'ack_not_on_wire': 'a command answered as acknowledged that the device never executed',
    'ack_spoiled_reply': 'a command acknowledged although the reply was spoiled',
    'reference': 'a reference word the client never set, or an invalid one taken',
    'monitor_only_write': 'a write to a monitor-only device',
    'not_stopped': 'a motor still running after the shutdown stops',
    'shutdown_write': 'a write to a device left running (stop_on_shutdown false) after the '
                      'shutdown',
}


def outcome_of_error(error: Optional[BaseException]) -> str:
    """Return the outcome of a bus future from its exception (None: acknowledged)."""
    if error is None:
        return ACKNOWLEDGED
    if isinstance(error, CommandRefused):
        return REJECTED if 'rejected by' in str(error) else NOT_SENT
    return UNACKNOWLEDGED  # a transport error, or anything else: it may have been sent


def outcome_of_reply(success: bool, message: str) -> str:
    """Return the outcome of a service reply (a Trigger response) from its text."""
    if success:
        return ACKNOWLEDGED
    if 'rejected by' in message:
        return REJECTED
    if 'nothing sent' in message or 'not sent' in message:
        return NOT_SENT
    return UNACKNOWLEDGED  # not confirmed, or an unknown failure: it may have been sent


def reference_valid(percent: float) -> bool:
    """Return whether ``percent`` is a reference a drive may get: finite, in [-200, 200)."""
    return math.isfinite(percent) and fc_profile_scaling.MIN_PERCENT <= percent < \
        fc_profile_scaling.MAX_PERCENT


def as_float32(value: float) -> float:
    """Return ``value`` as a std_msgs/Float32 carries it."""
    return struct.unpack('<f', struct.pack('<f', value))[0]


@dataclass
class Request:
    """A command the client asked for, and what it was told."""

    index: int  # its place among everything the client did or was told
    device: str
    command: str
    asked_seq: int  # the line had carried this many requests when it was asked
    asked_s: float
    answer_index: Optional[int] = None
    answered_seq: Optional[int] = None
    answered_s: Optional[float] = None
    outcome: str = ''  # one of OUTCOMES; '' while never answered
    text: str = ''


@dataclass
class Notice:
    """What the bridge told the client about a device: 'offline', 'online' or 'tripped'."""

    index: int
    device: str
    kind: str
    seq: int
    time_s: float


@dataclass
class Reference:
    """A speed reference the client set; ``accepted`` None when it was not told (a topic)."""

    index: int
    device: str
    percent: float
    seq: int
    time_s: float
    accepted: Optional[bool]


@dataclass
class Shutdown:
    """
    The client stopped the bridge (SIGTERM to the node, or the bus's stop of everything).

    ``ends_runs``: from here on no run image may go out. False for a signal the bridge takes
    some time later (it records when it was sent: nothing may be written after it to a
    device left running); the exit is recorded again with ``ends_runs``.
    """

    index: int
    seq: int
    time_s: float
    ends_runs: bool = True


class ClientLog:
    """
    The client's record, each entry with the line sequence at that moment.

    ``exact``: the client runs the bus in its own thread, so an answer is recorded at the
    moment the bus resolves it (see the module docstring).
    """

    def __init__(self, line_seq: Callable[[], int], clock: Callable[[], float] = time.monotonic,
                 exact: bool = False):
        self.line_seq = line_seq
        self.clock = clock
        self.exact = exact
        self.started_s = clock()
        self.requests: List[Request] = []
        self.notices: List[Notice] = []
        self.references: List[Reference] = []
        self.shutdowns: List[Shutdown] = []
        self._lock = threading.Lock()
        self._index = 0

    def _stamp(self) -> Tuple[int, int, float]:
        self._index += 1
        return self._index, self.line_seq(), self.clock()

    def ask(self, device: str, command: str) -> Request:
        """Record that ``command`` is asked for now (call just before asking)."""
        with self._lock:
            index, seq, now = self._stamp()
            request = Request(index, device, command, seq, now)
            self.requests.append(request)
            return request

    def answer(self, request: Request, outcome: str, text: str = '') -> None:
        """Record the answer to ``request`` (call the moment it is known)."""
        if outcome not in OUTCOMES:
            raise ValueError(f'unknown outcome {outcome!r}: allowed {", ".join(OUTCOMES)}')
        with self._lock:
            request.answer_index, request.answered_seq, request.answered_s = self._stamp()
            request.outcome, request.text = outcome, text

    def answer_future(self, request: Request, future) -> None:
        """Record the answer a bus future carries (use as its done callback)."""
        error = future.exception()
        self.answer(request, outcome_of_error(error),
                    str(error) if error is not None else str(future.result()))

    def notice(self, device: str, kind: str) -> None:
        """Record that the bridge reported ``device`` offline, online or tripped."""
        with self._lock:
            index, seq, now = self._stamp()
            self.notices.append(Notice(index, device, kind, seq, now))

    def reference(self, device: str, percent: float, accepted: Optional[bool]) -> None:
        """Record a speed reference set (``accepted`` as the client was told, or None)."""
        with self._lock:
            index, seq, now = self._stamp()
            self.references.append(Reference(index, device, percent, seq, now, accepted))

    def shutdown(self, ends_runs: bool = True) -> None:
        """Record that the bridge is told to stop everything and close (see Shutdown)."""
        with self._lock:
            self.shutdowns.append(Shutdown(*self._stamp(), ends_runs))

    def outcomes(self) -> Counter:
        """Return 'command outcome' -> count of the answered requests."""
        return Counter(f'{request.command} {request.outcome or "never answered"}'
                       for request in self.requests)


@dataclass(frozen=True)
class DeviceInfo:
    """One device on the line as the oracle knows it (its configuration, nothing else)."""

    name: str
    unit: int
    kind: str  # 'mcd', 'drive' or 'lvsg' (soak_line.KINDS)
    monitor_only: bool = False
    stop_on_shutdown: bool = True
    reference_pct: float = 0.0  # the configured speed reference (drives)

    @property
    def level(self) -> bool:
        """Return whether the device runs while its image says run (drives, the gateway)."""
        return self.kind != 'mcd'


@dataclass(frozen=True)
class Violation:
    """One broken invariant, with its reason in one line."""

    kind: str
    device: str
    seq: int
    text: str

    def line(self) -> str:
        """Return the violation as one readable line."""
        return f'{self.kind}: {self.text}'


@dataclass
class _Start:
    """A start request during the replay of one device."""

    request: Request
    own_seq: Optional[int] = None  # the frame that was its own write
    ended: str = ''  # why it no longer keeps a run image
    hard: str = ''  # why its own write may no longer go out


@dataclass
class _OwedStop:
    """A level device went offline holding a run: it must get a stop word after the outage."""

    notice: Notice
    start: _Start
    online: bool = False
    frames: int = 0  # requests to the device since it answered again


@dataclass
class _Replay:
    """The state of one device's replay."""

    device: DeviceInfo
    live: List[_Start] = field(default_factory=list)
    by_index: Dict[int, _Start] = field(default_factory=dict)
    latest: Optional[_Start] = None  # the latest start asked for
    latest_sent: Optional[_Start] = None  # the latest that may have reached the device
    owed_stop: Optional[_OwedStop] = None


class Oracle:
    """Check a run's two records against the invariants; see the module docstring."""

    def __init__(self, frames: Sequence[WireFrame], client: ClientLog,
                 devices: Iterable[DeviceInfo], slack: Optional[int] = None):
        self.frames = frames
        self.client = client
        self.exact = client.exact
        # One request may still wait in a simulator on its own thread when the client
        # records an answer, a notice or a stop (the master gave up on it, the simulator
        # takes it after): then an end takes effect one request later. Default: none for an
        # exact record (a virtual line has no such wait), one otherwise.
        self.slack = (0 if self.exact else 1) if slack is None else slack
        self.devices = {device.name: device for device in devices}
        self._by_unit: Dict[int, List[WireFrame]] = defaultdict(list)
        for frame in frames:
            self._by_unit[frame.unit].append(frame)

    # -- wording ------------------------------------------------------------------------
    def _at(self, time_s: Optional[float], seq: Optional[int]) -> str:
        if time_s is None:
            return 'never'
        return f'{time_s - self.client.started_s:.3f} s (frame {seq})'

    def _frame_text(self, frame: WireFrame) -> str:
        what = frame.control.text if frame.control is not None else \
            f'function {frame.function:02X}h ({frame.data[:4].hex(" ")})'
        return f'{what} at {self._at(frame.time_s, frame.seq)}'

    def _who(self, device: DeviceInfo) -> str:
        return f'{device.name} (address {device.unit})'

    def _asked(self, request: Request) -> str:
        return f'{request.command} asked at {self._at(request.asked_s, request.asked_seq)}'

    def _answered(self, request: Request) -> str:
        return f'answered {request.outcome} at ' \
            f'{self._at(request.answered_s, request.answered_seq)}'

    # -- the checks ---------------------------------------------------------------------
    def check(self, final_states: Optional[Dict[str, str]] = None) -> List[Violation]:
        """
        Return every violation, in line order.

        ``final_states``: device -> '' if its simulated motor is stopped after the shutdown,
        else what still runs (None: the run had no shutdown to check).
        """
        violations: List[Violation] = []
        for device in self.devices.values():
            if device.monitor_only:
                violations += self._monitor_only(device)
                continue
            violations += self._starts(device)
            violations += self._acknowledged(device)
            if device.kind == 'drive':
                violations += self._references(device)
        if final_states is not None:
            violations += self._shutdown(final_states)
        return sorted(violations, key=lambda violation: violation.seq)

    def _monitor_only(self, device: DeviceInfo) -> List[Violation]:
        return [Violation('monitor_only_write', device.name, frame.seq,
                          f'{self._who(device)} is monitor only but received '
                          f'{self._frame_text(frame)}')
                for frame in self._by_unit[device.unit] if frame.writes]

    # -- invariants 1 and 2: starts and run images ----------------------------------------
    def _events(self, device: DeviceInfo) -> List[tuple]:
        """Return the device's frames and the client's records about it, in line order."""
        items = [(frame.seq, 0, frame.seq, 'frame', frame)
                 for frame in self._by_unit[device.unit]]
        for request in self.client.requests:
            if request.device != device.name:
                continue
            shift = self.slack if request.command in STOP_CLASS else 0
            items.append((request.asked_seq + shift, 1, request.index, 'ask', request))
            if request.answered_seq is not None:
                items.append((request.answered_seq + self.slack, 1, request.answer_index,
                              'answer', request))
        items += [(notice.seq + self.slack, 1, notice.index, 'notice', notice)
                  for notice in self.client.notices
                  if notice.device == device.name]
        items += [(shutdown.seq + self.slack, 1, shutdown.index, 'shutdown', shutdown)
                  for shutdown in self.client.shutdowns if shutdown.ends_runs]
        return sorted(items, key=lambda item: item[:3])

    def _starts(self, device: DeviceInfo) -> List[Violation]:
        replay = _Replay(device)
        violations: List[Violation] = []
        for seq, _, _, kind, item in self._events(device):
            if kind == 'frame':
                violations += self._on_frame(replay, item)
            elif kind == 'ask':
                self._on_ask(replay, item)
            elif kind == 'answer':
                self._on_answer(replay, item)
            elif kind == 'notice':
                self._on_notice(replay, item)
            else:
                reason = f'the shutdown at {self._at(item.time_s, item.seq)}'
                self._end(replay, item.index, reason, hard=True)
            replay.live = [start for start in replay.live if not self._spent(start, seq)]
        return violations

    def _on_frame(self, replay: _Replay, frame: WireFrame) -> List[Violation]:
        control = frame.control if frame.executed else None
        owed = replay.owed_stop
        if owed is not None and control is not None:
            replay.owed_stop = None  # a stop word, or a run word the run rules judge
        elif owed is not None and owed.online:
            owed.frames += 1
            if owed.frames > STOP_AFTER_OUTAGE_FRAMES:
                replay.owed_stop = None
                return [Violation(
                    'no_stop_after_outage', replay.device.name, frame.seq,
                    f'{self._who(replay.device)} went offline at '
                    f'{self._at(owed.notice.time_s, owed.notice.seq)} holding the run of the '
                    f'{self._asked(owed.start.request)}, but executed no control write in '
                    f'the {STOP_AFTER_OUTAGE_FRAMES} requests after it answered again (up to '
                    f'{self._at(frame.time_s, frame.seq)})')]
        if control is None or not control.run:
            return []
        violation = self._explain(replay, frame)  # a late frame: still someone's own write
        if violation is None or frame.late:  # but its place among the records is not known
            return []
        return [violation]

    def _on_notice(self, replay: _Replay, notice: Notice) -> None:
        device = replay.device
        if notice.kind == 'online':
            if replay.owed_stop is not None:
                replay.owed_stop.online = True
            return
        if notice.kind == 'offline' and device.level and replay.owed_stop is None:
            held = [start for start in replay.live if not start.ended and
                    start.request.outcome in (ACKNOWLEDGED, '') and
                    (start.own_seq is not None or not self.exact)]
            if held:
                replay.owed_stop = _OwedStop(notice, held[-1])
        reason = f'{device.name} reported {notice.kind} at {self._at(notice.time_s, notice.seq)}'
        self._end(replay, notice.index, reason, hard=True)

    def _on_ask(self, replay: _Replay, request: Request) -> None:
        if request.command == 'start':
            start = _Start(request)
            replay.live.append(start)
            replay.by_index[request.index] = start
            replay.latest = start
            if request.outcome in MAY_HAVE_RUN:  # the records are complete: known already
                replay.latest_sent = start
        elif request.command in STOP_CLASS and self.exact:
            self._end(replay, request.index, f'{self._asked(request)} (whatever its outcome)')

    def _on_answer(self, replay: _Replay, request: Request) -> None:
        if request.command == 'start':
            start = replay.by_index[request.index]
            if request.outcome in (ACKNOWLEDGED, UNACKNOWLEDGED):  # a newer start was sent
                reason = f'a newer start ({self._asked(request)}) was {self._answered(request)}'
                for older in replay.live:
                    if older.request.index < request.index and not older.ended:
                        older.ended = reason
            if request.outcome != ACKNOWLEDGED and not start.ended:
                start.ended = f'the client was told it failed: {self._answered(request)}'
        elif request.command in STOP_CLASS:
            if not self.exact:
                self._end(replay, request.index, f'{self._asked(request)} was '
                          f'{self._answered(request)} (whatever its outcome)')
            if request.outcome in (ACKNOWLEDGED, UNACKNOWLEDGED):
                reason = f'{self._asked(request)} was carried out ({self._answered(request)})'
                for start in replay.live:
                    if start.request.index < request.index and not start.hard:
                        start.hard = reason

    @staticmethod
    def _end(replay: _Replay, index: int, reason: str, hard: bool = False) -> None:
        """End every start asked before ``index`` (hard: its own write may not go out)."""
        for start in replay.live:
            if start.request.index < index:
                start.ended = start.ended or reason
                if hard:
                    start.hard = start.hard or reason

    def _spent(self, start: _Start, seq: int) -> bool:
        """Return whether a start can explain nothing after ``seq`` (``latest`` keeps it)."""
        request = start.request
        window_passed = request.answered_seq is not None and \
            request.answered_seq + self.slack < seq
        return bool(start.ended) and (start.own_seq is not None or window_passed or
                                      request.outcome not in MAY_HAVE_RUN)

    def _own_window(self, request: Request, seq: int) -> bool:
        """Return whether frame ``seq`` may be the start's own write."""
        if seq <= request.asked_seq:
            return False
        if request.answered_seq is None:
            return True
        if self.exact:  # the line's last request at the answer; or, for a lost reply, the
            # next one if the simulator took the write only after the master gave up (a
            # starved simulator thread on a loaded machine)
            if seq == request.answered_seq:
                return True
            return request.outcome == UNACKNOWLEDGED and seq == request.answered_seq + 1 \
                and not self._device_frame(request, request.answered_seq)
        return seq <= request.answered_seq + self.slack

    def _device_frame(self, request: Request, seq: int) -> bool:
        """Return whether line frame ``seq`` went to the device of ``request``."""
        return 0 < seq <= len(self.frames) and \
            self.frames[seq - 1].unit == self.devices[request.device].unit

    def _may_keep(self, start: _Start, seq: int) -> bool:
        """Return whether the start keeps a run image at frame ``seq`` (keepalive)."""
        request = start.request
        if start.ended or seq <= request.asked_seq:
            return False
        written = start.own_seq is not None or not self.exact
        if request.outcome in (ACKNOWLEDGED, ''):
            return written
        if request.outcome == UNACKNOWLEDGED:
            return written and seq <= request.answered_seq + self.slack
        return False

    def _explain(self, replay: _Replay, frame: WireFrame) -> Optional[Violation]:
        """Return a violation unless a start in force explains the run write ``frame``."""
        device = replay.device
        own = [start for start in replay.live
               if start.own_seq is None and start.request.outcome in MAY_HAVE_RUN and
               self._own_window(start.request, frame.seq)]
        kept = device.level and any(self._may_keep(start, frame.seq) for start in replay.live)
        if kept and not (self.exact and own):
            return None
        if own:  # the most likely owner: one whose own write may still go out, the latest
            start = max(own, key=lambda candidate: (not candidate.hard,
                                                    candidate.request.index))
            start.own_seq = frame.seq
            if start.hard:
                return Violation('start_after_stop', device.name, frame.seq,
                                 f'{self._who(device)}: {self._frame_text(frame)} was the '
                                 f'own write of the {self._asked(start.request)}, but '
                                 f'{start.hard}')
            return None
        kind, why = self._why_not(replay, frame)
        return Violation(kind, device.name, frame.seq,
                         f'{self._who(device)}: {self._frame_text(frame)} with no start in '
                         f'force: {why}')

    def _why_not(self, replay: _Replay, frame: WireFrame) -> Tuple[str, str]:
        latest = replay.latest_sent or replay.latest
        if latest is None:
            return 'run_without_start', 'no start was asked for before it'
        request = latest.request
        asked = f'the latest {self._asked(request)}'
        if request.outcome in (NOT_SENT, REJECTED):
            return 'run_without_start', f'{asked} was {self._answered(request)}'
        if request.outcome == UNACKNOWLEDGED and request.answered_seq + self.slack < frame.seq:
            return 'run_after_failed_start', f'{asked} was {self._answered(request)}'
        if latest.ended:
            return 'run_after_end', f'{asked} had ended: {latest.ended}'
        if latest.own_seq is not None:
            return 'start_twice', f'{asked} was already written at frame {latest.own_seq}'
        if self.exact and request.answered_seq is not None and frame.seq < \
                request.answered_seq:
            return 'run_without_start', f'{asked} was {self._answered(request)}: its own ' \
                'write is the request just before that answer, not this one'
        return 'run_without_start', f'{asked} cannot explain it ' \
            f'({request.outcome or "never answered"})'

    # -- invariant 3: acknowledged commands ---------------------------------------------
    def _acknowledged(self, device: DeviceInfo) -> List[Violation]:
        violations = []
        for request in self.client.requests:
            if request.device != device.name or request.outcome != ACKNOWLEDGED:
                continue
            expected = EXPECTED_WRITES[device.kind].get(request.command)
            problem = f'{device.kind} devices have no {request.command} write' \
                if expected is None else self._find_writes(device, request, expected)
            if problem:
                kind = 'ack_spoiled_reply' if problem.startswith('spoiled') else \
                    'ack_not_on_wire'
                violations.append(Violation(
                    kind, device.name, request.answered_seq,
                    f'{self._who(device)}: {self._asked(request)} was '
                    f'{self._answered(request)}, but {problem}'))
        return violations

    def _find_writes(self, device: DeviceInfo, request: Request,
                     expected: Tuple[Tuple[str, ...], ...]) -> str:
        """Return '' if the device executed the command's writes before its answer."""
        count = len(expected)
        if self.exact:
            # The line's last requests before the answer; only if they are not the command's
            # writes, the ones just after (taken late by a held-up simulator). Two identical
            # commands back to back must not trade frames: the first window that fits wins.
            last = request.answered_seq
            for shift in range(self.slack + 1):
                later = list(self.frames[max(0, last + shift - count):last + shift])
                if len(later) == count and all(self._is_write(frame, device, labels)
                                               for frame, labels in zip(later, expected)):
                    last += shift
                    break
            frames = list(self.frames[max(0, last - count):last])
            if len(frames) < count or not all(
                    self._is_write(frame, device, labels)
                    for frame, labels in zip(frames, expected)):
                seen = '; '.join(f'{self._frame_text(frame)} to address {frame.unit}'
                                 + ('' if frame.executed else ' (not executed)')
                                 for frame in frames) or 'nothing'
                wanted = ', then '.join('/'.join(labels) for labels in expected)
                return f"the device did not execute its write(s) ({wanted}): the line's " \
                    f'last request(s) before the answer: {seen}'
            spoiled = [frame for frame in frames if not frame.acknowledged]
            if spoiled:
                return f"spoiled: the device's reply to {self._frame_text(spoiled[0])} " \
                    f'carried the fault {spoiled[0].fault!r}'
            return ''
        frames = [frame for frame in self._by_unit[device.unit]
                  if request.asked_seq < frame.seq <= request.answered_seq + self.slack]
        for start in range(len(frames) - count + 1):
            run = frames[start:start + count]
            if all(frame.seq == run[0].seq + offset and frame.acknowledged and
                   self._is_write(frame, device, labels)
                   for offset, (frame, labels) in enumerate(zip(run, expected))):
                return ''
        return 'the device executed no such write between the call and its answer'

    @staticmethod
    def _is_write(frame: WireFrame, device: DeviceInfo, labels: Tuple[str, ...]) -> bool:
        return frame.unit == device.unit and frame.executed and frame.control is not None \
            and frame.control.label in labels

    # -- invariant 4: references ---------------------------------------------------------
    def _references(self, device: DeviceInfo) -> List[Violation]:
        violations = []
        words = {fc_profile_scaling.percent_to_word(device.reference_pct): 'the configured'}
        current = next(iter(words))
        items = [(frame.seq, 0, frame.seq, frame) for frame in self._by_unit[device.unit]
                 if frame.executed and frame.control is not None and
                 frame.control.reference is not None]
        items += [(reference.seq, 1, reference.index, reference)
                  for reference in self.client.references if reference.device == device.name]
        for _, _, _, item in sorted(items, key=lambda entry: entry[:3]):
            if isinstance(item, Reference):
                valid = reference_valid(item.percent)
                if item.accepted and not valid:
                    violations.append(Violation(
                        'reference', device.name, item.seq,
                        f'{self._who(device)}: the bridge took the reference {item.percent} % '
                        f'at {self._at(item.time_s, item.seq)}; allowed [-200, 200)'))
                if valid and item.accepted is not False:
                    current = fc_profile_scaling.percent_to_word(item.percent)
                    words.setdefault(current, f'{item.percent:g} %')
                continue
            word = item.control.reference
            latest_only = self.exact and not item.late  # a late frame: any set before it
            if (latest_only and word != current) or word not in words:
                expected = f'0x{current:04X}' if latest_only else 'none of them'
                violations.append(Violation(
                    'reference', device.name, item.seq,
                    f'{self._who(device)}: {self._frame_text(item)} carries a reference the '
                    f'client did not set (its latest: {expected})'))
        return violations

    # -- invariant 6: the shutdown -------------------------------------------------------
    def _shutdown(self, final_states: Dict[str, str]) -> List[Violation]:
        violations = []
        last = self.client.shutdowns[0] if self.client.shutdowns else None  # the first told
        end_seq = len(self.frames)
        for device in self.devices.values():
            running = final_states.get(device.name, '')
            if device.stop_on_shutdown and running and not device.monitor_only:
                violations.append(Violation(
                    'not_stopped', device.name, end_seq,
                    f'{self._who(device)} still runs after the shutdown: {running}'))
            if not device.stop_on_shutdown and last is not None:
                violations += [Violation('shutdown_write', device.name, frame.seq,
                                         f'{self._who(device)} has stop_on_shutdown false but '
                                         f'received {self._frame_text(frame)} after the '
                                         'shutdown')
                               for frame in self._by_unit[device.unit]
                               if frame.seq > last.seq + self.slack and frame.writes]
        return violations


def summarize(violations: Sequence[Violation]) -> Counter:
    """Return kind -> count."""
    return Counter(violation.kind for violation in violations)
