"""
A simulated AP ASCII line: MCD starters answering AP ASCII on a pty, faults injectable.

The starters are the same :class:`McdModel` as the Modbus simulator's; NAK, BEL, silence
and garbage can be injected per address.

Behaviour as ``protocols.md`` and manual 000 section 10 describe it: a slave ACKs its own
address fragment, NAKs a fragment with a bad LRC, answers a refused command with BEL and
stays silent for addresses it does not serve.
"""

from dataclasses import dataclass
import os
import select
import threading
import time
from typing import Dict, Optional

from drive_bridge.protocol import ap_ascii
from drive_bridge.sim.faults import AP_ASCII_FAULTS, FaultInjector, FaultPlan
from drive_bridge.sim.mcd_model import McdModel, ModuleError
from drive_bridge.sim.pty_link import PtyLink

_COMMAND_VALUES = {'B10': 1, 'B12': 2, 'B14': 3, 'B16': 4, 'B18': 5}
STALE_PARTIAL_S = 0.1  # a partial fragment older than this is dropped


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
        self._selected: Optional[int] = None
        self._message_fault: Optional[str] = None
        self._buffer = b''
        self._last_byte_s = 0.0
        self._running = False
        self._thread: Optional[threading.Thread] = None

    def inject(self, unit: int, fault: str, count: int = 1) -> None:
        """Make the next ``count`` replies of ``unit`` a NAK, BEL, silence, garbage or slow."""
        self.faults.inject(unit, fault, count)

    def open_pty(self, link_path: str = '') -> str:
        """Open a pty pair and serve on its master; return the slave's path."""
        self._pty = PtyLink(link_path)
        self._master = self._pty.master
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
        if self._pty is not None:
            self._pty.close()

    def _serve(self) -> None:
        while self._running:
            ready, _, _ = select.select([self._master], [], [], 0.01)
            now = self.clock()
            if ready:
                try:
                    data = os.read(self._master, 1024)
                except OSError:
                    data = b''
                if data:
                    self._buffer += data
                    self._last_byte_s = now
                    self._process()
            if self._buffer and now - self._last_byte_s > STALE_PARTIAL_S:
                self._buffer = b''

    def _process(self) -> None:
        while self._buffer:
            fragment, consumed = ap_ascii.decode_fragment(self._buffer, self.lrc_includes_eot)
            if consumed == 0:
                return
            self._buffer = self._buffer[consumed:]
            if fragment is not None:
                with self.lock:
                    self.stats.fragments += 1
                    reply = self._answer(fragment)
                if reply:
                    self._send(reply)

    def _send(self, reply: bytes) -> None:
        """Write a reply; wait while the pty is full (another writer on the line), never die."""
        deadline = time.monotonic() + 1.0
        while reply and time.monotonic() < deadline:
            try:
                reply = reply[os.write(self._master, reply):]
            except BlockingIOError:
                select.select([], [self._master], [], 0.05)
            except OSError:
                return  # the pty closed: the server is stopping

    def _answer(self, fragment: ap_ascii.Fragment) -> bytes:
        if fragment.kind == 'address':
            self._selected = None
            unit = fragment.address
            if unit not in self.devices or unit in self.silent_units:
                self.stats.unserved += 1
                return b''
            if not fragment.lrc_ok:
                return self._count(bytes([ap_ascii.NAK]))
            # A random fault goes to the address or the message fragment, at most one an
            # exchange; an injected one to the next reply, as inject() says.
            fault = self.faults.draw(unit)
            self._message_fault = None
            if fault is not None and not self.faults.last_queued and \
                    self.faults.random_int(0, 1):
                fault, self._message_fault = None, fault
            if fault is None or fault == 'slow':
                self._selected = unit
            return self._with_fault(fault, bytes([ap_ascii.ACK]))
        unit, self._selected = self._selected, None
        if unit is None:
            return b''
        if not fragment.lrc_ok:
            return self._count(bytes([ap_ascii.NAK]))
        fault, self._message_fault = self._message_fault, None
        if fault in ('nak', 'bel'):  # the fragment is not acted on
            return self._with_fault(fault, b'')
        return self._with_fault(fault, self._execute(self.devices[unit], fragment.code))

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

    def _with_fault(self, fault: Optional[str], reply: bytes) -> bytes:
        """Return ``reply``, or what replaces it for ``fault`` (a slow one after a delay)."""
        if fault is None:
            return self._count(reply)
        self.stats.faults_injected += 1
        if fault == 'slow':
            time.sleep(self.faults.plan.slow_s)
            return self._count(reply)
        return self._count({
            'nak': bytes([ap_ascii.NAK]), 'bel': bytes([ap_ascii.BEL]), 'silence': b'',
            'garbage': self.faults.random_bytes(5, 0x20, 0x7E)}[fault])

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
