"""
A simulated USB RS-485 adapter and line settings: between the master's pty and the devices.

:class:`AdapterRelay` opens the simulator's port (or the wire pacer's) as its upstream and
offers the master a pty of its own, as the wire pacer does, and adds what real adapters and
lines do:

- ``echo``: the adapter hears what it sends (2-wire RS-485 without echo suppression): the
  master reads its own bytes back;
- ``latency_s``: bytes reach the master in batches, one every ``latency_s`` (an FTDI
  adapter's latency timer, 16 ms by default);
- ``babble_per_s``: noise bytes reach the master at this rate while it listens (another
  master, a device sending on its own, an unterminated line);
- ``device_line``: the devices' own baud rate and stop bits. The master's port settings are
  read from the pty (``termios.tcgetattr``); at other settings nothing crosses (a UART at
  another baud rate frames no byte). A pty carries no parity (Linux clears it), so parity
  counts only through the stop bits it implies (8E1 and 8N2 differ; 8E1 and 8O1 do not).

Standard library only.
"""

from dataclasses import dataclass
import os
import random
import select
import termios
import threading
import time
import tty
from typing import Callable, Dict, Optional

from drive_bridge.sim.pty_link import PtyLink

SPEEDS: Dict[int, int] = {getattr(termios, f'B{rate}'): rate for rate in (
    1200, 2400, 4800, 9600, 19200, 38400, 57600, 115200, 230400)}
IDLE_WAIT_S = 0.5


@dataclass(frozen=True)
class SerialSetting:
    """A baud rate and the stop bits a port uses (what a pty shows of its settings)."""

    baudrate: int
    stopbits: int

    def describe(self) -> str:
        """Return the setting in words."""
        return f'{self.baudrate} baud, {self.stopbits} stop bit(s)'


def parse_device_line(text: str) -> SerialSetting:
    """Parse ``BAUD[:PARITY[:STOPBITS]]``; stop bits default 2 with parity N, else 1."""
    parts = text.split(':')
    try:
        if len(parts) > 3 or (len(parts) > 1 and parts[1] not in ('N', 'E', 'O')):
            raise ValueError
        baudrate = int(parts[0])
        stopbits = int(parts[2]) if len(parts) > 2 else (2 if parts[1:2] == ['N'] else 1)
        if baudrate not in SPEEDS.values() or stopbits not in (1, 2):
            raise ValueError
    except ValueError:
        raise ValueError(f'{text!r}: give BAUD[:PARITY[:STOPBITS]], e.g. 9600:E or 19200:N:2, '
                         f'baud one of {", ".join(map(str, SPEEDS.values()))}') from None
    return SerialSetting(baudrate, stopbits)


def port_setting(fd: int) -> Optional[SerialSetting]:
    """Return the baud rate and stop bits a terminal is set to (None: unknown)."""
    try:
        attributes = termios.tcgetattr(fd)
    except (termios.error, OSError):
        return None
    rate = SPEEDS.get(attributes[5])
    if rate is None:
        return None
    return SerialSetting(rate, 2 if attributes[2] & termios.CSTOPB else 1)


@dataclass(frozen=True)
class AdapterBehaviour:
    """What the simulated adapter and line do (all off by default)."""

    echo: bool = False
    latency_s: float = 0.0
    babble_per_s: float = 0.0
    device_line: Optional[SerialSetting] = None
    seed: int = 1

    @property
    def active(self) -> bool:
        """Return whether the relay has anything to do."""
        return self.echo or self.latency_s > 0 or self.babble_per_s > 0 or \
            self.device_line is not None


class AdapterRelay:
    """Run an :class:`AdapterBehaviour` on a thread between the master's pty and upstream."""

    def __init__(self, behaviour: AdapterBehaviour, clock: Callable[[], float] = time.monotonic):
        self.behaviour = behaviour
        self.clock = clock
        self.path = ''
        self.dropped_bytes = 0  # bytes that crossed at the wrong settings (nothing arrived)
        self.babbled_bytes = 0
        self._random = random.Random(behaviour.seed)
        self._pty: Optional[PtyLink] = None
        self._upstream = -1
        self._to_master = bytearray()
        self._next_flush_s = 0.0
        self._next_babble_s = 0.0
        self._wake_r, self._wake_w = os.pipe()
        self._thread: Optional[threading.Thread] = None
        self._running = False

    def open_pty(self, upstream_path: str, link_path: str = '') -> str:
        """Open ``upstream_path`` (the devices) and a pty for the master; return its path."""
        self._upstream = os.open(upstream_path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        if os.isatty(self._upstream):
            tty.setraw(self._upstream)
        self._pty = PtyLink(link_path)
        self.path = self._pty.path
        return self.path

    def start(self) -> 'AdapterRelay':
        """Relay on a background thread."""
        if self._pty is None:
            raise RuntimeError('open_pty() the relay before start()')
        now_s = self.clock()
        self._next_flush_s = now_s + self.behaviour.latency_s
        self._next_babble_s = now_s + self._babble_interval_s()
        self._running = True
        self._thread = threading.Thread(target=self._run, name='adapter-relay', daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop relaying; close both ports and the master's symlink (idempotent)."""
        self._running = False
        if self._thread is not None:
            os.write(self._wake_w, b'x')
            self._thread.join(timeout=5)
            self._thread = None
        for fd in (self._upstream, self._wake_r, self._wake_w):
            try:
                os.close(fd)
            except OSError:
                pass
        self._upstream = -1
        if self._pty is not None:
            self._pty.close()
            self._pty = None

    def settings_match(self) -> bool:
        """Return whether the master's port is set as the devices are (always, unset)."""
        wanted = self.behaviour.device_line
        return wanted is None or port_setting(self._pty.slave) == wanted

    # -- thread -------------------------------------------------------------------------
    def _babble_interval_s(self) -> float:
        rate = self.behaviour.babble_per_s
        return self._random.expovariate(rate) if rate > 0 else float('inf')

    def _run(self) -> None:
        master = self._pty.master
        watched = [self._wake_r, master, self._upstream]
        while self._running:
            readable, _, _ = select.select(watched, [], [], self._wait_s())
            for fd in readable:
                if fd == self._wake_r:
                    os.read(fd, 64)
                    continue
                data = _read(fd)
                if data is None:
                    continue
                if not data:
                    watched.remove(fd)
                    continue
                self._relay(data, from_master=fd == master)
            self._babble()
            self._flush()

    def _wait_s(self) -> float:
        due = [self._next_babble_s]
        if self._to_master:
            due.append(self._next_flush_s if self.behaviour.latency_s > 0 else 0.0)
        return min(IDLE_WAIT_S, max(0.0, min(due) - self.clock()))

    def _relay(self, data: bytes, from_master: bool) -> None:
        if from_master and self.behaviour.echo:
            self._to_master += data  # the adapter's receiver hears its own transmitter
        if not self.settings_match():
            self.dropped_bytes += len(data)
            return
        if from_master:
            _write(self._upstream, data)
        else:
            self._to_master += data

    def _babble(self) -> None:
        now_s = self.clock()
        while self._next_babble_s <= now_s:
            self._to_master.append(self._random.randrange(256))
            self.babbled_bytes += 1
            self._next_babble_s += self._babble_interval_s()

    def _flush(self) -> None:
        """Hand the master what is due: at once, or at each tick of the latency timer."""
        latency_s, now_s = self.behaviour.latency_s, self.clock()
        if latency_s > 0:
            if now_s < self._next_flush_s:
                return
            ticks = int((now_s - self._next_flush_s) / latency_s) + 1
            self._next_flush_s += ticks * latency_s
        if self._to_master:
            _write(self._pty.master, bytes(self._to_master))
            self._to_master.clear()


def _read(fd: int) -> Optional[bytes]:
    """Return what ``fd`` has (None: nothing now; b'': its other end closed)."""
    try:
        return os.read(fd, 4096)
    except BlockingIOError:
        return None
    except OSError:
        return b''


def _write(fd: int, data: bytes) -> None:
    """Write ``data``; a side whose buffer is full or gone loses it, as a line would."""
    try:
        os.write(fd, data)
    except OSError:
        pass
