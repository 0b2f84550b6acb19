"""
The serial port that the native transports share: open, close, read until a deadline.

A local port is opened exclusively (POSIX: pyserial's ``exclusive=True``, an ``flock``), so
that a second master (the node and ``drive-bridge`` on the same line) gets one clear line
naming the holder instead of a line where two masters talk over each other.

A local POSIX port is read by its descriptor, and a wait for ``n`` bytes is one ``select``
with the terminal's ``VMIN`` set to ``n``: the kernel's line discipline reports the port
readable only once ``n`` bytes are there (``VTIME`` 0), so the thread wakes once when a
reply is complete instead of once per byte or per USB batch. Where ``VMIN`` cannot be set
(not a terminal) or has no effect on ``select`` (not Linux), the same loop wakes per chunk
and reads what is there: only the number of wake-ups differs, never what is read.
"""

import errno
import logging
import os
import select
import time
from typing import Callable, List, Optional

from drive_bridge.errors import LineBabble, LinkDown
from drive_bridge.transport.base import Transport
from drive_bridge.transport.link import (
    LinkSettings, open_hint, port_framing, port_missing, PortFraming, URL_PREFIXES)
from drive_bridge.transport.port_owner import in_use_text
import serial

PARITIES = {'N': serial.PARITY_NONE, 'E': serial.PARITY_EVEN, 'O': serial.PARITY_ODD}
STOPBITS = {1: serial.STOPBITS_ONE, 2: serial.STOPBITS_TWO}
try:  # tcflush on a port whose adapter was unplugged raises termios.error, not OSError
    import termios
    from termios import error as TermiosError
except ImportError:  # not POSIX
    termios = None

    class TermiosError(Exception):
        """Placeholder where termios does not exist."""
PORT_ERRORS = (serial.SerialException, OSError, TermiosError)
EARLY_WAKE_S = 0.002  # how much before a reply's end a wait for it ends
MIN_DRAIN_SILENCE_S = 0.005
MAX_VMIN = 255  # VMIN is one byte of the terminal's settings
LOG = logging.getLogger(__name__)


def exclusive_open(port: str) -> bool:
    """Return whether ``port`` is opened exclusively (a local device on POSIX, not a URL)."""
    return os.name == 'posix' and not port.startswith(URL_PREFIXES)


def lock_refused(error: Exception) -> bool:
    """Return whether opening failed because another program holds the port's lock."""
    return 'exclusively lock' in str(error) or \
        getattr(error, 'errno', None) in (errno.EAGAIN, errno.EWOULDBLOCK)


def error_number(error: BaseException) -> Optional[int]:
    """
    Return the errno behind a failed open, if any tells it.

    pyserial raises termios' error as it is (``(22, 'Invalid argument')``), or wraps it in a
    SerialException whose errno is lost (``Could not configure port: ...``) but whose
    context still holds it.
    """
    seen: Optional[BaseException] = error
    while seen is not None:
        code = getattr(seen, 'errno', None)
        if code is None and isinstance(seen, TermiosError) and seen.args and \
                isinstance(seen.args[0], int):
            code = seen.args[0]
        if code:
            return code
        seen = seen.__cause__ or seen.__context__
    return None


def refusal_text(settings: LinkSettings, framing: PortFraming, error: BaseException) -> str:
    """Return why the port did not open, in one line naming what it refused."""
    port, code = settings.port, error_number(error)
    if code == errno.EINVAL:
        return (f'cannot open {port}: the port refused baudrate {settings.baudrate}, parity '
                f'{framing.parity}, stopbits {framing.stopbits} (EINVAL): its adapter or '
                'driver does not take these settings; check baudrate, parity and stopbits')
    if code == errno.ENOTTY:
        return (f'cannot open {port}: it is not a serial port (it has no terminal settings, '
                'ENOTTY)')
    if code == errno.EISDIR:
        return f'cannot open {port}: it is a directory, not a serial port'
    return f'cannot open {settings.describe()}: {error}' + open_hint(settings)


def open_serial(settings: LinkSettings, framing: PortFraming,
                open_port: Optional[Callable[..., object]] = None):
    """
    Open the link's port with ``framing``; raise LinkDown with the reason in words.

    ``open_port`` defaults to pyserial's ``serial_for_url``. A local port is opened
    exclusively: another program holding it is named.
    """
    exclusive = {'exclusive': True} if exclusive_open(settings.port) else {}
    try:
        return (open_port or serial.serial_for_url)(
            settings.port, baudrate=settings.baudrate, bytesize=serial.EIGHTBITS,
            parity=PARITIES[framing.parity], stopbits=STOPBITS[framing.stopbits],
            timeout=0,  # reads return what is there; the waiting is done by select
            **exclusive)
    except (*PORT_ERRORS, ValueError) as error:
        if exclusive and lock_refused(error):
            raise LinkDown(f'bus offline: {in_use_text(settings.port)}') from error
        raise LinkDown(f'bus offline: {refusal_text(settings, framing, error)}') from error


def note_framing(framing: PortFraming, noted: bool) -> bool:
    """Log the note of a framing that is not the link's (a pty), once; return if noted."""
    if framing.note and not noted:
        LOG.info(framing.note)
        return True
    return noted


def direct_descriptor(port) -> Optional[int]:
    """Return the descriptor to read ``port`` by, if it is a plain local POSIX port."""
    if os.name != 'posix' or type(port) is not serial.Serial:  # not a URL handler's class
        return None
    fd = port.fileno()
    os.set_blocking(fd, False)  # as pyserial opens it: a read returns what is there
    return fd


def terminal_settings(fd: int) -> Optional[List]:
    """Return the terminal settings of ``fd`` to set VMIN with, or None if it has none."""
    if termios is None:
        return None
    try:
        settings = termios.tcgetattr(fd)
    except (TermiosError, OSError):
        return None
    settings[6] = list(settings[6])
    settings[6][termios.VTIME] = 0  # VMIN alone decides readiness (pyserial sets VTIME 0)
    return settings


def _read_ready(fd: int, count: int) -> bytes:
    """Return up to ``count`` bytes that are there (a tty with VMIN 0 returns none)."""
    try:
        return os.read(fd, count)
    except BlockingIOError:
        return b''


class SerialPortTransport(Transport):
    """Own one pyserial port (device path or URL such as ``socket://``); subclasses talk."""

    reports_request_sent = True  # each request is written by _write, which reports it

    def __init__(self, settings: LinkSettings,
                 open_port: Callable[..., object] = serial.serial_for_url):
        super().__init__(settings)
        self._open_port = open_port
        self._port = None
        self._fd: Optional[int] = None  # a local POSIX port's descriptor, read directly
        self._terminal: Optional[List] = None  # its terminal settings, to set VMIN with
        self._vmin = -1  # the VMIN set on it now (-1: not known)
        self._framing_noted = False  # the note of a pty's framing is logged once

    @property
    def connected(self) -> bool:
        """Return whether the port is open."""
        return self._port is not None

    def framing(self) -> PortFraming:
        """Return the framing to open the port with (a pty: without parity)."""
        return port_framing(self.settings)

    def connect(self) -> None:
        """Open the port; raise LinkDown with the reason in words."""
        self.close()
        settings = self.settings
        if port_missing(settings):
            raise LinkDown(f'bus offline: {settings.port} not found')
        framing = self.framing()
        self._port = open_serial(settings, framing, self._open_port)
        self._framing_noted = note_framing(framing, self._framing_noted)
        self._fd = direct_descriptor(self._port)
        self._terminal = None if self._fd is None else terminal_settings(self._fd)
        self._vmin = -1

    def close(self) -> None:
        """Close the port (idempotent), leaving VMIN as pyserial set it (0)."""
        port, self._port = self._port, None
        if port is not None:
            try:
                if self._terminal is not None and self._vmin > 0:
                    self._set_vmin(0)
            except PORT_ERRORS:
                pass  # the adapter is gone: nothing to leave behind
            try:
                port.close()
            except PORT_ERRORS:
                pass
        self._fd, self._terminal = None, None

    def _require_port(self) -> None:
        if self._port is None:
            raise LinkDown('bus offline: not connected')

    def _port_failed(self, error: Exception) -> LinkDown:
        """Close the port after an I/O error and return the LinkDown to raise."""
        self.close()
        if port_missing(self.settings):
            return LinkDown(f'bus offline: {self.settings.port} not found')
        return LinkDown(f'bus offline: {self.settings.describe()}: {error}')

    def _write(self, data: bytes, deadline: float, report: bool = True) -> None:
        """Write ``data`` whole, then report it sent (:attr:`on_request_sent`) if asked."""
        self._write_whole(data, deadline)
        if report:
            self.on_request_sent()

    def _write_whole(self, data: bytes, deadline: float) -> None:
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
            missing = count - len(data)
            chunk = self._read_some(missing, remaining, at_least=missing)
            if not chunk and remaining <= 0:
                break
            data += chunk
        return data

    def _read_some(self, count: int, timeout_s: float, at_least: int = 1) -> bytes:
        """
        Read up to ``count`` bytes, waiting at most ``timeout_s`` for ``at_least`` of them.

        Returns fewer than ``at_least`` (what is there) when the time is up, and on a port
        without VMIN as soon as anything is there. The port is open with timeout 0 (a read
        returns what is there), so no call here changes the port's timeout (pyserial
        reconfigures the port on every change) and one select is the only wake-up while
        nothing arrives.
        """
        if self._fd is not None:
            return self._read_descriptor(count, timeout_s, at_least)
        port = self._port
        if not port.in_waiting:
            if timeout_s <= 0:
                return b''
            ready, _, _ = select.select([port], [], [], timeout_s)
            if not ready:
                return b''
        return port.read(count)

    def _read_descriptor(self, count: int, timeout_s: float, at_least: int) -> bytes:
        """
        :meth:`_read_some` on a local POSIX port: ``os.read`` on its non-blocking descriptor.

        pyserial's ``read`` costs a ``select`` and its timeout bookkeeping on every call, even
        when the bytes are there; this is the bus thread's most frequent call. What is there
        is taken first; for the rest VMIN is set to the bytes still missing, so the ``select``
        returns when they are there (one wake-up) or when the time is up (then what is there
        is read). VMIN is changed only when a wait needs it: on a USB adapter that delivers
        a whole reply at once it stays as it is.
        """
        fd = self._fd
        data = _read_ready(fd, count)
        wanted = min(at_least, count)
        if len(data) >= wanted or timeout_s <= 0 or (data and self._terminal is None):
            return data
        if self._terminal is not None:
            self._set_vmin(min(wanted - len(data), MAX_VMIN))
        ready, _, _ = select.select([fd], [], [], timeout_s)
        more = _read_ready(fd, count - len(data))
        if ready and not more:  # readable but nothing: the adapter is gone (pyserial's words)
            raise serial.SerialException('device reports readiness to read but returned no '
                                         'data (device disconnected or multiple access on '
                                         'port?)')
        return data + more

    def _set_vmin(self, count: int) -> None:
        """Make ``select`` report the port readable only with ``count`` bytes there."""
        if count != self._vmin:
            self._terminal[6][termios.VMIN] = count
            termios.tcsetattr(self._fd, termios.TCSANOW, self._terminal)
            self._vmin = count

    def _await_bytes(self, count: int, char_s: float, deadline: float) -> None:
        """
        Sleep until ``count`` more bytes can have crossed the wire, unless they are there.

        A reply cannot arrive faster than its wire time: one sleep instead of a wake-up per
        byte or per USB batch. On a link that does not pace bytes (a pty, TCP) they are
        already there and nothing waits. A port with VMIN needs no sleep: the read that
        follows wakes once, when the bytes are there.
        """
        if self._terminal is not None:
            return
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
