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

from dataclasses import replace
import errno
import logging
import os
import select
import time
from typing import Callable, List, Optional

from drive_bridge.errors import LinkDown
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


class SerialLine:
    """
    One pyserial port (a device path or a URL such as ``socket://``) as a byte line.

    The :class:`~drive_bridge.transport.exchange.ByteLine` of the serial transports: it moves
    bytes and bounds every wait; what the bytes mean and when to send is the line
    discipline's (:mod:`.exchange`). Not thread-safe: the bus thread owns it.
    """

    def __init__(self, settings: LinkSettings, port: str,
                 open_port: Callable[..., object] = serial.serial_for_url):
        self.settings = settings
        self.port_name = port  # the path or URL opened (rtu_over_tcp: socket://host:port)
        self._open_port = open_port
        self._port = None
        self._fd: Optional[int] = None  # a local POSIX port's descriptor, read directly
        self._terminal: Optional[List] = None  # its terminal settings, to set VMIN with
        self._vmin = -1  # the VMIN set on it now (-1: not known)
        self._framing_noted = False  # the note of a pty's framing is logged once

    @property
    def is_open(self) -> bool:
        """Return whether the port is open."""
        return self._port is not None

    def connect(self) -> None:
        """Open the port; raise LinkDown with the reason in words."""
        self.close()
        settings = replace(self.settings, port=self.port_name)
        if port_missing(settings):
            raise LinkDown(f'bus offline: {settings.port} not found')
        framing = port_framing(settings) if settings.is_serial else \
            PortFraming(settings.effective_parity, settings.effective_stopbits)
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

    def write(self, data: bytes, deadline: float) -> None:
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

    def read(self, count: int, timeout_s: float, at_least: int = 1) -> bytes:
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

    def wait_quiet(self, timeout_s: float) -> bytes:
        """
        Wait ``timeout_s`` and return whatever arrived meanwhile (b'': the line kept quiet).

        VMIN is left as it is: the wait ends early only if that many bytes arrive, and what
        came is read at the end without a wait.
        """
        if timeout_s > 0:
            select.select([self._port if self._fd is None else self._fd], [], [], timeout_s)
        return self.read(MAX_VMIN, 0.0)

    def _read_descriptor(self, count: int, timeout_s: float, at_least: int) -> bytes:
        """
        :meth:`read` on a local POSIX port: ``os.read`` on its non-blocking descriptor.

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
