"""
Fault injection for the simulators: seeded, reproducible, counted by kind.

A :class:`FaultInjector` decides, reply by reply, whether a device's reply goes wrong and
how. Faults come from an explicit queue per address (``inject``) first, then at random with
probability ``rate`` from a ``random.Random(seed)``, so the same seed and the same request
sequence give the same faults. ``injected`` counts what was done per (address, kind), so a
test or the soak compares it with what the bus master counted.

Modbus RTU, AP ASCII and the FC protocol carry no transaction id, so a reply that comes
after the master gave up can be taken for the answer to its next request. ``late`` and
``late_batched`` make such replies; the serving thread never sleeps for any reply (see
:mod:`drive_bridge.sim.scheduled_writes`): it answers other requests meanwhile.

Modbus RTU kinds and what the master sees:

==============  ============================================================  ==============
kind            what the simulator does                                       master counts
==============  ============================================================  ==============
crc             sends the reply with its CRC inverted                         crc
no_reply        executes the request, sends nothing                           timeout
slow            sends the reply ``slow_s`` late (still inside the timeout)    slow reply
exception       does not execute; answers exception 06 (device busy)          exception
garbage         the right address, then bytes that are no reply               bad_frame
truncated       sends the first part of the reply only                        truncated
wrong_address   sends the reply under another address (valid CRC)             wrong_address
late            executes; sends the reply ``master_timeout_s + late_s``       timeout
                after the request arrived, from a timer
late_batched    executes; holds the reply until the next request (to any      timeout
                unit) on the same connection, then sends it just before
                that request's own reply
==============  ============================================================  ==============

A late or held reply is whole and valid; on Modbus TCP it keeps its own transaction id.
A plan that names no kinds draws these two as well; :func:`without_late` gives a tuple of
kinds without them.

AP ASCII kinds: ``nak`` (the fragment is NAKed, not acted on), ``bel`` (refused),
``silence``, ``garbage`` (printable bytes that are no reply), ``slow``, ``late`` and
``late_batched`` (held until the next fragment arrives). An exchange has two replies: an
injected fault hits the address fragment's ACK, or with ``fragment='message'`` the reply to
the message fragment (the address is ACKed normally).
"""

from collections import Counter, defaultdict, deque
from dataclasses import dataclass
import random
import threading
from typing import Deque, Dict, Iterable, Optional, Tuple

from drive_bridge.protocol import rtu
from drive_bridge.protocol.crc import append_crc

LATE_FAULTS = ('late', 'late_batched')  # whole replies after the master's timeout
MODBUS_FAULTS = ('crc', 'no_reply', 'slow', 'exception', 'garbage', 'truncated',
                 'wrong_address', *LATE_FAULTS)
MBAP_FAULTS = ('no_reply', 'slow', 'exception', *LATE_FAULTS)  # no CRC or RTU framing
AP_ASCII_FAULTS = ('nak', 'bel', 'silence', 'garbage', 'slow', *LATE_FAULTS)
AP_ASCII_FRAGMENTS = ('address', 'message')  # the two replies of an AP ASCII exchange
DEVICE_BUSY = 0x06  # Modbus exception: slave device busy (the request was not executed)
MASTER_TIMEOUT_S = 0.5  # the bridge's default 'timeout'


def without_late(kinds: Iterable[str]) -> Tuple[str, ...]:
    """Return ``kinds`` without ``late`` and ``late_batched`` (replies inside the timeout)."""
    return tuple(kind for kind in kinds if kind not in LATE_FAULTS)


@dataclass(frozen=True)
class FaultPlan:
    """Random faults: each reply goes wrong with probability ``rate``, kinds drawn evenly."""

    rate: float = 0.0
    kinds: Tuple[str, ...] = MODBUS_FAULTS
    seed: int = 1
    slow_s: float = 0.1  # delay of a 'slow' reply; keep it inside the master's timeout
    units: Optional[frozenset] = None  # None: every address
    late_s: float = 0.02  # how long after the master's timeout a 'late' reply comes
    master_timeout_s: float = MASTER_TIMEOUT_S  # the master's timeout, for 'late' replies

    def reply_due_s(self, fault: Optional[str], request_end_s: float,
                    normal_due_s: float) -> float:
        """
        Return when the reply to a request is to be written, given its fault.

        ``request_end_s``: when the request's last byte arrived; ``normal_due_s``: when the
        reply would be written without a fault (at once, or at its wire time).
        """
        if fault == 'slow':
            return normal_due_s + self.slow_s
        if fault == 'late':
            return max(normal_due_s, request_end_s + self.master_timeout_s + self.late_s)
        return normal_due_s


def parse_fault_plan(text: str, allowed: Tuple[str, ...], seed: int = 1,
                     slow_s: float = 0.1, late_s: float = 0.02,
                     master_timeout_s: float = MASTER_TIMEOUT_S) -> FaultPlan:
    """
    Parse ``RATE[:KIND,KIND...]`` (e.g. ``0.1`` or ``0.05:crc,no_reply``) into a plan.

    No kinds: every kind of ``allowed``. Raises ValueError with the allowed values in words.
    """
    rate_text, _, kinds_text = text.partition(':')
    try:
        rate = float(rate_text)
    except ValueError:
        raise ValueError(f'fault rate {rate_text!r} is not a number (0 to 1)') from None
    kinds = tuple(kind for kind in kinds_text.split(',') if kind) or allowed
    plan = FaultPlan(rate, kinds, seed, slow_s, late_s=late_s,
                     master_timeout_s=master_timeout_s)
    check_plan(plan, allowed)
    return plan


def check_plan(plan: FaultPlan, allowed: Iterable[str]) -> None:
    """Raise ValueError if the plan's rate or kinds are not usable here."""
    allowed = tuple(allowed)
    if not 0.0 <= plan.rate <= 1.0:
        raise ValueError(f'fault rate {plan.rate} is outside 0 to 1')
    unknown = [kind for kind in plan.kinds if kind not in allowed]
    if unknown or not plan.kinds:
        raise ValueError(f'unknown fault kind {", ".join(unknown) or "(none)"}: allowed '
                         f'{", ".join(allowed)}')
    for name in ('slow_s', 'late_s', 'master_timeout_s'):
        if not getattr(plan, name) >= 0:  # NaN is refused too
            raise ValueError(f'{name} must not be negative ({getattr(plan, name)})')


class FaultInjector:
    """Decide and apply faults for one simulated line; safe to share between threads."""

    def __init__(self, allowed: Tuple[str, ...] = MODBUS_FAULTS,
                 plan: Optional[FaultPlan] = None):
        self.allowed = allowed
        self.plan = FaultPlan(kinds=allowed)
        self.injected: Counter = Counter()  # (unit, kind) -> count
        self.last_queued = False  # whether the last draw came from inject() (not at random)
        self.last_fragment: Optional[str] = None  # the fragment inject() gave the last draw
        self._queued: Dict[int, Deque[Tuple[str, Optional[str]]]] = defaultdict(deque)
        self._lock = threading.Lock()
        self._random = random.Random(1)
        if plan is not None:
            self.set_plan(plan)

    def set_plan(self, plan: FaultPlan) -> None:
        """Start random faults by ``plan`` (re-seeds the generator)."""
        check_plan(plan, self.allowed)
        with self._lock:
            self.plan = plan
            self._random = random.Random(plan.seed)

    def inject(self, unit: int, kind: str, count: int = 1,
               fragment: Optional[str] = None) -> None:
        """
        Make the next ``count`` replies of ``unit`` go wrong by ``kind``.

        ``fragment``: which reply of an exchange of two it hits (AP ASCII's 'address' or
        'message'); the server reads it as :attr:`last_fragment` after :meth:`draw`.
        """
        if kind not in self.allowed:
            raise ValueError(f'unknown fault kind {kind!r}: allowed {", ".join(self.allowed)}')
        with self._lock:
            self._queued[unit].extend([(kind, fragment)] * count)

    def draw(self, unit: int, usable: Optional[Tuple[str, ...]] = None) -> Optional[str]:
        """
        Return the fault for the next reply of ``unit``, or None; count it as injected.

        ``usable`` narrows the kinds that this connection can carry (Modbus TCP has no
        CRC); a queued or drawn kind outside it is not injected.
        """
        with self._lock:
            queue = self._queued.get(unit)
            self.last_queued = bool(queue)
            self.last_fragment = None
            if queue:
                kind, self.last_fragment = queue.popleft()
            else:
                kind = self._random_kind(unit)
            if kind is None or (usable is not None and kind not in usable):
                return None
            self.injected[(unit, kind)] += 1
            return kind

    def _random_kind(self, unit: int) -> Optional[str]:
        plan = self.plan
        if plan.rate <= 0 or (plan.units is not None and unit not in plan.units):
            return None
        if self._random.random() >= plan.rate:
            return None
        return self._random.choice(plan.kinds)

    def totals(self) -> Counter:
        """Return injected faults per kind, over every address."""
        with self._lock:
            totals: Counter = Counter()
            for (_, kind), count in self.injected.items():
                totals[kind] += count
            return totals

    def random_bytes(self, count: int, low: int = 0, high: int = 255) -> bytes:
        """Return ``count`` bytes from the injector's generator (reproducible)."""
        with self._lock:
            return bytes(self._random.randint(low, high) for _ in range(count))

    def random_int(self, low: int, high: int) -> int:
        """Return an integer in [low, high] from the injector's generator."""
        with self._lock:
            return self._random.randint(low, high)


def mangle_rtu_reply(kind: str, reply: bytes, injector: FaultInjector) -> Optional[bytes]:
    """Return the bytes to send instead of the RTU ``reply`` for fault ``kind`` (None: none)."""
    if kind == 'no_reply':
        return None
    if kind == 'crc':
        return reply[:-2] + bytes(byte ^ 0xFF for byte in reply[-2:])
    if kind == 'truncated':
        return reply[:injector.random_int(1, len(reply) - 1)]
    if kind == 'wrong_address':
        unit = reply[0] % 247 + 1
        return append_crc(bytes([unit]) + reply[1:-2])
    if kind == 'garbage':
        function = reply[1] & 0x7F
        noise = bytearray(injector.random_bytes(injector.random_int(4, 12)))
        if noise[0] & 0x7F == function:
            noise[0] ^= 0x40  # never the function code, so it cannot pass as a reply
        return reply[:1] + bytes(noise)
    return reply  # 'slow' and the late ones (timed by the server), 'exception'


def exception_reply(frame: rtu.RtuFrame) -> rtu.RtuFrame:
    """Return the 'device busy' exception the 'exception' fault answers with."""
    return rtu.exception_response(frame.unit, frame.function, DEVICE_BUSY)
