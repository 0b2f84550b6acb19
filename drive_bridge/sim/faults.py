"""
Fault injection for the simulators: seeded, reproducible, counted by kind.

A :class:`FaultInjector` decides, reply by reply, whether a device's reply goes wrong and
how. Faults come from an explicit queue per address (``inject``) first, then at random with
probability ``rate`` from a ``random.Random(seed)``, so the same seed and the same request
sequence give the same faults. ``injected`` counts what was done per (address, kind), so a
test or the soak compares it with what the bus master counted.

Modbus RTU kinds and what the master sees:

==============  =========================================================  ==============
kind            what the simulator does                                    master counts
==============  =========================================================  ==============
crc             sends the reply with its CRC inverted                      crc
no_reply        executes the request, sends nothing                        timeout
slow            sends the reply ``slow_s`` late (still inside the timeout)  slow reply
exception       does not execute; answers exception 06 (device busy)       exception
garbage         the right address, then bytes that are no reply            bad_frame
truncated       sends the first part of the reply only                     truncated
wrong_address   sends the reply under another address (valid CRC)          wrong_address
==============  =========================================================  ==============

AP ASCII kinds: ``nak`` (the fragment is NAKed, not acted on), ``bel`` (refused),
``silence``, ``garbage`` (printable bytes that are no reply) and ``slow``.
"""

from collections import Counter, defaultdict, deque
from dataclasses import dataclass
import random
import threading
from typing import Deque, Dict, Iterable, Optional, Tuple

from drive_bridge.protocol import rtu
from drive_bridge.protocol.crc import append_crc

MODBUS_FAULTS = ('crc', 'no_reply', 'slow', 'exception', 'garbage', 'truncated',
                 'wrong_address')
MBAP_FAULTS = ('no_reply', 'slow', 'exception')  # Modbus TCP has no CRC or RTU framing
AP_ASCII_FAULTS = ('nak', 'bel', 'silence', 'garbage', 'slow')
DEVICE_BUSY = 0x06  # Modbus exception: slave device busy (the request was not executed)


@dataclass(frozen=True)
class FaultPlan:
    """Random faults: each reply goes wrong with probability ``rate``, kinds drawn evenly."""

    rate: float = 0.0
    kinds: Tuple[str, ...] = MODBUS_FAULTS
    seed: int = 1
    slow_s: float = 0.1  # delay of a 'slow' reply; keep it inside the master's timeout
    units: Optional[frozenset] = None  # None: every address


def parse_fault_plan(text: str, allowed: Tuple[str, ...], seed: int = 1,
                     slow_s: float = 0.1) -> FaultPlan:
    """
    Parse ``RATE[:KIND,KIND...]`` (e.g. ``0.1`` or ``0.05:crc,no_reply``) into a plan.

    Raises ValueError with the allowed values in words.
    """
    rate_text, _, kinds_text = text.partition(':')
    try:
        rate = float(rate_text)
    except ValueError:
        raise ValueError(f'fault rate {rate_text!r} is not a number (0 to 1)') from None
    kinds = tuple(kind for kind in kinds_text.split(',') if kind) or allowed
    plan = FaultPlan(rate, kinds, seed, slow_s)
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
    if plan.slow_s < 0:
        raise ValueError('slow_s must not be negative')


class FaultInjector:
    """Decide and apply faults for one simulated line; safe to share between threads."""

    def __init__(self, allowed: Tuple[str, ...] = MODBUS_FAULTS,
                 plan: Optional[FaultPlan] = None):
        self.allowed = allowed
        self.plan = FaultPlan(kinds=allowed)
        self.injected: Counter = Counter()  # (unit, kind) -> count
        self.last_queued = False  # whether the last draw came from inject() (not at random)
        self._queued: Dict[int, Deque[str]] = defaultdict(deque)
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

    def inject(self, unit: int, kind: str, count: int = 1) -> None:
        """Make the next ``count`` replies of ``unit`` go wrong by ``kind``."""
        if kind not in self.allowed:
            raise ValueError(f'unknown fault kind {kind!r}: allowed {", ".join(self.allowed)}')
        with self._lock:
            self._queued[unit].extend([kind] * count)

    def draw(self, unit: int, usable: Optional[Tuple[str, ...]] = None) -> Optional[str]:
        """
        Return the fault for the next reply of ``unit``, or None; count it as injected.

        ``usable`` narrows the kinds that this connection can carry (Modbus TCP has no
        CRC); a queued or drawn kind outside it is not injected.
        """
        with self._lock:
            queue = self._queued.get(unit)
            self.last_queued = bool(queue)
            if queue:
                kind = queue.popleft()
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
    return reply  # 'slow' (delayed by the server) and 'exception' (answered before)


def exception_reply(frame: rtu.RtuFrame) -> rtu.RtuFrame:
    """Return the 'device busy' exception the 'exception' fault answers with."""
    return rtu.exception_response(frame.unit, frame.function, DEVICE_BUSY)
