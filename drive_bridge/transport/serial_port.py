"""
The serial port that the native transports share: open, close, read until a deadline.

A local port is opened exclusively (POSIX: pyserial's ``exclusive=True``, an ``flock``), so
that a second master (the node and ``drive-bridge`` on the same line) gets one clear line
naming the holder instead of a line where two masters talk over each other.
"""

import errno
import os
import select
import time
from typing import Callable, Optional

from drive_bridge.errors import LineBabble, LinkDown
from drive_bridge.transport.base import Transport
from drive_bridge.transport.link import LinkSettings, open_hint, port_missing, URL_PREFIXES
from drive_bridge.transport.port_owner import in_use_text
import serial

PARITIES = {'N': serial.PARITY_NONE, 'E': serial.PARITY_EVEN, 'O': serial.PARITY_ODD}
STOPBITS = {1: serial.STOPBITS_ONE, 2: serial.STOPBITS_TWO}
try:  # tcflush on a port whose adapter was unplugged raises termios.error, not OSError
    from termios import error as TermiosError
except ImportError:  # not POSIX
    class TermiosError(Exception):
        """Placeholder where termios does not exist."""
PORT_ERRORS = (serial.SerialException, OSError, TermiosError)
EARLY_WAKE_S = 0.002  # how much before a reply's end a wait for it ends
MIN_DRAIN_SILENCE_S = 0.005


def exclusive_open(port: str) -> bool:
    """Return whether ``port`` is opened exclusively (a local device on POSIX, not a URL)."""
    return os.name == 'posix' and not port.startswith(URL_PREFIXES)


def lock_refused(error: Exception) -> bool:
    """Return whether opening failed because another program holds the port's lock."""
    return 'exclusively lock' in str(error) or \
        getattr(error, 'errno', None) in (errno.EAGAIN, errno.EWOULDBLOCK)


def direct_descriptor(port) -> Optional[int]:
    """Return the descriptor to read ``port`` by, if it is a plain local POSIX port."""
    if os.name != 'posix' or type(port) is not serial.Serial:  # not a URL handler's class
        return None
    fd = port.fileno()
    os.set_blocking(fd, False)  # as pyserial opens it: a read returns what is there
    return fd


def _read_ready(fd: int, count: int) -> bytes:
    """Return up to ``count`` bytes that are there (a tty with VMIN 0 returns none)."""
    try:
        return os.read(fd, count)
    except BlockingIOError:
        return b''


class SerialPortTransport(Transport):
    """Own one pyserial port (device path or URL such as ``socket://``); subclasses talk."""

    def __init__(self, settings: LinkSettings,
                 open_port: Callable[..., object] = serial.serial_for_url):
        super().__init__(settings)
        self._open_port = open_port
        self._port = None
        self._fd: Optional[int] = None  # a local POSIX port's descriptor, read directly

    @property
    def connected(self) -> bool:
        """Return whether the port is open."""
        return self._port is not None

    def framing(self) -> tuple:
        """Return (parity, stop bits) to open the port with."""
        return self.settings.effective_parity, self.settings.effective_stopbits

    def connect(self) -> None:
        """Open the port; raise LinkDown with the reason in words."""
        self.close()
        settings = self.settings
        if port_missing(settings):
            raise LinkDown(f'bus offline: {settings.port} not found')
        parity, stopbits = self.framing()
        exclusive = {'exclusive': True} if exclusive_open(settings.port) else {}
        try:
            self._port = self._open_port(
                settings.port, baudrate=settings.baudrate, bytesize=serial.EIGHTBITS,
                parity=PARITIES[parity], stopbits=STOPBITS[stopbits],
                timeout=0,  # reads return what is there; the waiting is done by select
                **exclusive)
        except (*PORT_ERRORS, ValueError) as error:
            if exclusive and lock_refused(error):
                raise LinkDown(f'bus offline: {in_use_text(settings.port)}') from error
            raise LinkDown(f'bus offline: cannot open {settings.describe()}: {error}'
                           + open_hint(settings)) from error
        self._fd = direct_descriptor(self._port)

    def close(self) -> None:
        """Close the port (idempotent)."""
        port, self._port, self._fd = self._port, None, None
        if port is not None:
            try:
                port.close()
            except PORT_ERRORS:
                pass

    def _require_port(self) -> None:
        if self._port is None:
            raise LinkDown('bus offline: not connected')

    def _port_failed(self, error: Exception) -> LinkDown:
        """Close the port after an I/O error and return the LinkDown to raise."""
        self.close()
        if port_missing(self.settings):
            return LinkDown(f'bus offline: {self.settings.port} not found')
        return LinkDown(f'bus offline: {self.settings.describe()}: {error}')

    def _write(self, data: bytes, deadline: float) -> None:
        """Write ``data`` whole; on a local POSIX port straight to its descriptor."""
        if self._fd is None:
            self._port.write(data)
            return
        fd, view = self._fd, memoryview(data)
        while view:
            try:
                view = view[os.write(fd, view):]
                continue
            except BlockingIOError:
                pass
            _, ready, _ = select.select([], [fd], [], max(0.0, deadline - time.monotonic()))
            if not ready:  # pyserial would wait for ever
                raise serial.SerialTimeoutException('the port takes no more bytes (write '
                                                    'timeout)')

    def _read(self, count: int, deadline: float) -> bytes:
        """Read up to ``count`` bytes; return early only when the deadline passes."""
        data = b''
        while len(data) < count:
            remaining = deadline - time.monotonic()
            chunk = self._read_some(count - len(data), remaining)
            if not chunk and remaining <= 0:
                break
            data += chunk
        return data

    def _read_some(self, count: int, timeout_s: float) -> bytes:
        """
        Read up to ``count`` bytes, waiting at most ``timeout_s`` for the first of them.

        The port is open with timeout 0 (a read returns what is there), so no call here
        changes the port's timeout (pyserial reconfigures the port on every change) and one
        select is the only wake-up while nothing arrives.
        """
        if self._fd is not None:
            return self._read_descriptor(count, timeout_s)
        port = self._port
        if not port.in_waiting:
            if timeout_s <= 0:
                return b''
            ready, _, _ = select.select([port], [], [], timeout_s)
            if not ready:
                return b''
        return port.read(count)

    def _read_descriptor(self, count: int, timeout_s: float) -> bytes:
        """
        :meth:`_read_some` on a local POSIX port: ``os.read`` on its non-blocking descriptor.

        pyserial's ``read`` costs a ``select`` and its timeout bookkeeping on every call, even
        when the bytes are there; this is the bus thread's most frequent call.
        """
        fd = self._fd
        data = _read_ready(fd, count)
        if data or timeout_s <= 0:
            return data
        ready, _, _ = select.select([fd], [], [], timeout_s)
        if not ready:
            return b''
        data = _read_ready(fd, count)
        if not data:  # readable but nothing: the adapter is gone (pyserial's words for it)
            raise serial.SerialException('device reports readiness to read but returned no '
                                         'data (device disconnected or multiple access on '
                                         'port?)')
        return data

    def _await_bytes(self, count: int, char_s: float, deadline: float) -> None:
        """
        Sleep until ``count`` more bytes can have crossed the wire, unless they are there.

        A reply cannot arrive faster than its wire time: one sleep instead of a wake-up per
        byte or per USB batch. On a link that does not pace bytes (a pty, TCP) they are
        already there and nothing waits.
        """
        waiting = self._port.in_waiting
        if waiting >= count:
            return
        # Wake a little early: bytes reach us in batches (USB adapters, the pacer), and the
        # read that follows waits for the last batch itself.
        pause_s = min((count - waiting) * char_s - max(2 * char_s, EARLY_WAKE_S),
                      deadline - time.monotonic())
        if pause_s > 0.0005:
            time.sleep(pause_s)

    def _drain(self, deadline: float, silence_s: float) -> None:
        """
        Drop what still arrives after a bad reply, until ``silence_s`` of silence.

        Bounded by the transaction's deadline (at least a few silences from now): a line
        that is still talking then is babbling (another master, or a faulty device), a link
        fault of its own kind rather than one more bad reply.
        """
        silence_s = max(MIN_DRAIN_SILENCE_S, silence_s)
        limit = max(deadline, time.monotonic() + 4 * silence_s)
        dropped = 0
        while True:
            # A full silence each time (never cut short by the limit, which would take a
            # late wait for a pause): bounded by the limit plus one silence.
            chunk = self._read_some(256, silence_s)
            if not chunk:
                return
            dropped += len(chunk)
            if time.monotonic() >= limit:
                raise LineBabble(f'bus offline: {self.settings.describe()}: the line keeps '
                                 f'talking ({dropped} bytes past a bad reply, no pause within '
                                 f'the {self.settings.timeout_s:g} s transaction): another '
                                 'master or a faulty device is sending')
