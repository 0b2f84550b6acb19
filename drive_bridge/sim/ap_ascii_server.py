"""
A simulated AP ASCII line: MCD starters answering AP ASCII on a pty, faults injectable.

The starters are the same :class:`McdModel` as the Modbus simulator's; faults can be
injected per address (:data:`~drive_bridge.sim.faults.AP_ASCII_FAULTS`):

==============  ===========================================================================
kind            what the simulator does with the reply it hits
==============  ===========================================================================
nak             NAKs the fragment and does not act on it
bel             refuses the fragment with BEL (not acted on)
silence         acts on the fragment, sends nothing
garbage         acts on the fragment, sends printable bytes that are no reply
slow            acts on the fragment, sends its reply ``slow_s`` late
late            acts on the fragment, sends its reply ``master_timeout_s + late_s`` after
                the fragment arrived, from a timer (other fragments are answered meanwhile)
late_batched    acts on the fragment, holds its reply until the next fragment arrives and
                sends it just before that fragment's own reply
==============  ===========================================================================

An exchange has two replies: the ACK of the address fragment, then the ACK (a command) or
data reply (a request) of the message fragment. ``inject(unit, kind, fragment='address')``
spoils the next address ACK of ``unit``; ``fragment='message'`` ACKs the address and spoils
the reply to that exchange's message fragment (``inject(20, 'late', fragment='message')``:
the starter executes B10 and its ACK comes after the master's timeout). A random fault hits
either, at most one an exchange. The serving thread never sleeps for a reply.

Behaviour as ``protocols.md`` and manual 000 section 10 describe it: a slave ACKs its own
address fragment, NAKs a fragment with a bad LRC, answers a refused command with BEL and
stays silent for addresses it does not serve.
"""

from dataclasses import dataclass
import os
import select
import threading
import time
from typing import Dict, Optional, Tuple

from drive_bridge.protocol import ap_ascii
from drive_bridge.sim.faults import AP_ASCII_FAULTS, AP_ASCII_FRAGMENTS, FaultInjector, FaultPlan
from drive_bridge.sim.mcd_model import McdModel, ModuleError
from drive_bridge.sim.pty_link import PtyLink
from drive_bridge.sim.scheduled_writes import ScheduledWrites

_COMMAND_VALUES = {'B10': 1, 'B12': 2, 'B14': 3, 'B16': 4, 'B18': 5}
STALE_PARTIAL_S = 0.1  # a partial fragment older than this is dropped
SELECT_TIMEOUT_S = 0.01  # the longest wait of the serving loop for bytes or a due reply
_TIMED_FAULTS = ('slow', 'late', 'late_batched')  # the reply itself, at another time
_SELECTING_FAULTS = (None, *_TIMED_FAULTS)  # the address is ACKed: the unit is selected


@dataclass
class AsciiStats:
    """What the simulated line saw."""

    fragments: int = 0
    acks: int = 0
    naks: int = 0
    bels: int = 0
    replies: int = 0
    faults_injected: int = 0
    unserved: int = 0


class PtyWriter:
    """The pty master as the scheduled writes' stream: a full pty is waited for, briefly."""

    def __init__(self, master: int):
        self.master = master
        self.closed = False
        self.tap = None  # the wire trace's WireTap, or None

    def write(self, reply: bytes) -> None:
        """Write a reply; wait while the pty is full (another writer on the line), never die."""
        deadline = time.monotonic() + 1.0
        if self.tap is not None:
            self.tap.frame(False, reply)
        while reply and time.monotonic() < deadline:
            try:
                reply = reply[os.write(self.master, reply):]
            except BlockingIOError:
                select.select([], [self.master], [], 0.05)
            except OSError:
                return  # the pty closed: the server is stopping


class ApAsciiSimServer:
    """Serve MCD models over AP ASCII on a pty, on a thread of its own."""

    def __init__(self, devices: Dict[int, McdModel], status_style: str = 'hex',
                 lrc_includes_eot: Optional[bool] = None,
                 fault_plan: Optional[FaultPlan] = None):
        self.devices = devices
        self.status_style = status_style
        self.lrc_includes_eot = lrc_includes_eot  # None: accept both
        self.lock = threading.RLock()
        self.stats = AsciiStats()
        self.silent_units: set = set()
        self.faults = FaultInjector(AP_ASCII_FAULTS, fault_plan)
        self.clock = time.monotonic
        self.pty_path = ''
        self._pty: Optional[PtyLink] = None
        self._master = -1
        self._stream = PtyWriter(-1)
        self.writes = ScheduledWrites(lambda: self.clock())
        self._selected: Optional[int] = None
        self._message_fault: Optional[str] = None
        self._buffer = b''
        self._last_byte_s = 0.0
        self._running = False
        self._thread: Optional[threading.Thread] = None
        self.tap = None  # set before start: the wire trace's WireTap

    def inject(self, unit: int, fault: str, count: int = 1, fragment: str = 'address') -> None:
        """
        Spoil the next ``count`` exchanges of ``unit`` by ``fault`` (a kind of AP_ASCII_FAULTS).

        ``fragment``: 'address' (the address fragment's ACK goes wrong) or 'message' (the
        address is ACKed and the reply to the message fragment goes wrong).
        """
        if fragment not in AP_ASCII_FRAGMENTS:
            raise ValueError(f'unknown fragment {fragment!r}: allowed '
                             f'{", ".join(AP_ASCII_FRAGMENTS)}')
        self.faults.inject(unit, fault, count, fragment)

    def open_pty(self, link_path: str = '') -> str:
        """Open a pty pair and serve on its master; return the slave's path."""
        self._pty = PtyLink(link_path)
        self._master = self._pty.master
        self._stream = PtyWriter(self._master)
        self._stream.tap = self.tap
        self.pty_path = self._pty.path
        return self.pty_path

    def start(self) -> 'ApAsciiSimServer':
        """Serve on a background thread."""
        self._running = True
        self._thread = threading.Thread(target=self._serve, name='ap-ascii-sim', daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop serving and close the pty."""
        self._running = False
        if self._thread:
            self._thread.join(timeout=5)
        self._stream.closed = True
        self.writes.clear()
        if self._pty is not None:
            self._pty.close()

    def _serve(self) -> None:
        while self._running:
            timeout_s = self.writes.timeout_s(self.clock(), SELECT_TIMEOUT_S)
            ready, _, _ = select.select([self._master], [], [], timeout_s)
            now = self.clock()
            if ready:
                try:
                    data = os.read(self._master, 1024)
                except OSError:
                    data = b''
                if data and self.tap is not None:
                    self.tap.frame(True, data)
                if data:
                    self._buffer += data
                    self._last_byte_s = now
                    self._process()
            if self._buffer and now - self._last_byte_s > STALE_PARTIAL_S:
                self._buffer = b''
            self.writes.flush_due(self.clock())

    def _process(self) -> None:
        while self._buffer:
            fragment, consumed = ap_ascii.decode_fragment(self._buffer, self.lrc_includes_eot)
            if consumed == 0:
                return
            self._buffer = self._buffer[consumed:]
            if fragment is not None:
                self.writes.release_held(self._stream)  # a fragment came: held replies go
                with self.lock:
                    self.stats.fragments += 1
                    reply, fault = self._answer(fragment)
                if reply:
                    self._send(reply, fault)

    def _send(self, reply: bytes, fault: Optional[str]) -> None:
        """Write ``reply`` now, or later or held as its ``fault`` says; never wait here."""
        if fault == 'late_batched':
            self.writes.hold(self._stream, reply)
            return
        due = self.faults.plan.reply_due_s(fault, self._last_byte_s, self.clock())
        self.writes.write_at(due, self._stream, reply)

    def _answer(self, fragment: ap_ascii.Fragment) -> Tuple[bytes, Optional[str]]:
        """Return the reply to ``fragment`` and the fault that times it (None: at once)."""
        if fragment.kind == 'address':
            return self._answer_address(fragment)
        unit, self._selected = self._selected, None
        if unit is None:
            return b'', None
        if not fragment.lrc_ok:
            return self._count(bytes([ap_ascii.NAK])), None
        fault, self._message_fault = self._message_fault, None
        if fault in ('nak', 'bel'):  # the fragment is not acted on
            return self._with_fault(fault, b'')
        return self._with_fault(fault, self._execute(self.devices[unit], fragment.code))

    def _answer_address(self, fragment: ap_ascii.Fragment) -> Tuple[bytes, Optional[str]]:
        self._selected = None
        unit = fragment.address
        if unit not in self.devices or unit in self.silent_units:
            self.stats.unserved += 1
            return b'', None
        if not fragment.lrc_ok:
            return self._count(bytes([ap_ascii.NAK])), None
        # A fault goes to the address or the message fragment, at most one an exchange.
        fault = self.faults.draw(unit)
        self._message_fault = None
        if fault is not None and self._fault_hits_message():
            fault, self._message_fault = None, fault
        if fault in _SELECTING_FAULTS:
            self._selected = unit
        return self._with_fault(fault, bytes([ap_ascii.ACK]))

    def _fault_hits_message(self) -> bool:
        """Return whether the fault just drawn hits the message fragment's reply."""
        if self.faults.last_queued:  # injected: as inject() was told
            return self.faults.last_fragment == 'message'
        return bool(self.faults.random_int(0, 1))  # at random: either, evenly

    def _execute(self, model: McdModel, code: str) -> bytes:
        now = self.clock()
        if code in _COMMAND_VALUES:
            try:
                model.write_register(1, _COMMAND_VALUES[code], now)
            except ModuleError:
                return bytes([ap_ascii.BEL])
            return bytes([ap_ascii.ACK])
        model.advance(now)
        if code == 'C22':
            status = model.status_word() | (0x80 if model.local_comms_error else 0)
            return ap_ascii.data_fragment(ap_ascii.encode_status(status, self.status_style))
        if code == 'C18':
            return ap_ascii.data_fragment(ap_ascii.encode_status(model.trip_code,
                                                                 self.status_style))
        if code == 'D10':
            value = model.motor_current_a * model.config.current_register_scale
            return ap_ascii.data_fragment(ap_ascii.encode_data(min(9999, round(value))))
        if code == 'D12':
            value = min(9999, round(model.temperature_pct))
            return ap_ascii.data_fragment(ap_ascii.encode_data(value))
        return bytes([ap_ascii.BEL])

    def _with_fault(self, fault: Optional[str],
                    reply: bytes) -> Tuple[bytes, Optional[str]]:
        """Return ``reply``, or what replaces it for ``fault``, and the fault that times it."""
        if fault is None:
            return self._count(reply), None
        self.stats.faults_injected += 1
        if fault in _TIMED_FAULTS:
            return self._count(reply), fault
        return self._count({
            'nak': bytes([ap_ascii.NAK]), 'bel': bytes([ap_ascii.BEL]), 'silence': b'',
            'garbage': self.faults.random_bytes(5, 0x20, 0x7E)}[fault]), None

    def _count(self, reply: bytes) -> bytes:
        kinds = {bytes([ap_ascii.ACK]): 'acks', bytes([ap_ascii.NAK]): 'naks',
                 bytes([ap_ascii.BEL]): 'bels'}
        name = kinds.get(reply, 'replies' if reply else '')
        if name:
            setattr(self.stats, name, getattr(self.stats, name) + 1)
        return reply


def make_ap_ascii_server(models: Dict[int, str], **settings) -> ApAsciiSimServer:
    """Return a simulated AP ASCII line with one MCD per address: ``{20: 'mcd500'}``."""
    from drive_bridge.sim.mcd_model import McdSimConfig
    now = time.monotonic()
    return ApAsciiSimServer({unit: McdModel(McdSimConfig(model=model, **settings), now)
                             for unit, model in models.items()})
