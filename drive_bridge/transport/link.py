"""Link settings and checks that every transport shares (no pymodbus, no pyserial here)."""

from dataclasses import dataclass
import os
import stat
from typing import NamedTuple

from drive_bridge.protocol import rtu
from drive_bridge.transport.protocols import PROTOCOLS

URL_PREFIXES = ('socket://', 'rfc2217://', 'loop://')
PTY_MAJORS = range(136, 144)  # Linux (devices.txt): char 136-143 are the Unix98 pty slaves


@dataclass
class LinkSettings:
    """Where the bus is and how its bytes are framed; times in seconds."""

    protocol: str = 'modbus_rtu'
    port: str = '/dev/ttyUSB0'
    host: str = '127.0.0.1'
    tcp_port: int = 502
    baudrate: int = 9600
    parity: str = 'E'
    stopbits: int = 0  # 0 = Modbus standard: 2 with no parity, 1 with parity
    timeout_s: float = 0.5
    local_echo: bool = False
    reply_guard_s: float = 0.0  # the quarantine's guard; 0 = the protocol's own

    @property
    def guard_s(self) -> float:
        """Return how long after a failed transaction late replies are waited for."""
        return self.reply_guard_s or PROTOCOLS[self.protocol].reply_guard_s

    @property
    def effective_parity(self) -> str:
        """Return the parity in use (a protocol with fixed framing overrides the setting)."""
        fixed = PROTOCOLS[self.protocol].fixed_framing
        return fixed[0] if fixed else self.parity

    @property
    def effective_stopbits(self) -> int:
        """Return the stop bits in use (0: the protocol's default for the parity)."""
        spec = PROTOCOLS[self.protocol]
        if spec.fixed_framing:
            return spec.fixed_framing[1]
        return self.stopbits or spec.default_stopbits(self.parity)

    @property
    def is_serial(self) -> bool:
        """Return whether the bus is a local serial port."""
        return PROTOCOLS[self.protocol].is_serial

    @property
    def frame_gap_s(self) -> float:
        """Return the silence the protocol keeps between transactions on this link."""
        return PROTOCOLS[self.protocol].frame_gap_s(self.baudrate, self.effective_parity,
                                                    self.effective_stopbits)

    def describe(self) -> str:
        """Return the link in words, for messages."""
        if self.is_serial:
            return (f'{self.port} {self.baudrate} {self.effective_parity}'
                    f'{self.effective_stopbits}')
        return f'{self.protocol} {self.host}:{self.tcp_port}'


class PortFraming(NamedTuple):
    """The parity and stop bits a serial port is opened with, and why they differ, if so."""

    parity: str
    stopbits: int
    note: str = ''  # '' when they are the link's own


def pty_device(port: str) -> str:
    """
    Return the pseudo-terminal ``port`` leads to (``/dev/pts/3``), or '' if it is none.

    Told by the device number of the node the path resolves to (a symlink such as the
    simulator's ``--link`` is followed), not by its name.
    """
    if os.name != 'posix' or port.startswith(URL_PREFIXES):
        return ''
    try:
        status = os.stat(port)
    except OSError:
        return ''
    if not stat.S_ISCHR(status.st_mode) or os.major(status.st_rdev) not in PTY_MAJORS:
        return ''
    return os.path.realpath(port)


def port_framing(settings: LinkSettings) -> PortFraming:
    """
    Return the framing to open a serial port with: the link's, or without parity on a pty.

    A pty has no wire, so it has no parity either: Linux clears the parity flag a client
    asks for, and refuses (EINVAL) every later open that asks for it again. A pty is
    therefore opened without parity, and the note says so; whatever follows from the
    framing (character time, frame gap, the meaning of ``stopbits: 0``) keeps the link's.
    """
    parity, stopbits = settings.effective_parity, settings.effective_stopbits
    pty = '' if parity == 'N' else pty_device(settings.port)
    if not pty:
        return PortFraming(parity, stopbits)
    shown = settings.port if pty == settings.port else f'{settings.port} ({pty})'
    return PortFraming('N', stopbits, (
        f'{shown} is a pty: opened without parity (a pty has no wire, so no parity); '
        f'timing as configured, {settings.baudrate} baud 8{parity}{stopbits}'))


def port_missing(settings: LinkSettings) -> bool:
    """Return whether a serial device path does not exist (URLs are never missing)."""
    return settings.is_serial and not settings.port.startswith(URL_PREFIXES) and \
        not os.path.exists(settings.port)


def open_hint(settings: LinkSettings) -> str:
    """Return why a serial port may have failed to open, in words ('' if no idea)."""
    if settings.is_serial and not settings.port.startswith(URL_PREFIXES) and \
            not os.access(settings.port, os.R_OK | os.W_OK):
        return ' (permission denied: add the user to the dialout group)'
    return ''


def wire_time_s(settings: LinkSettings, request_bytes: int, reply_bytes: int) -> float:
    """Return the minimum time one RTU transaction occupies the line, gaps included."""
    char_s = rtu.character_time_s(settings.baudrate, settings.parity,
                                  settings.effective_stopbits)
    gap_s = rtu.frame_gap_s(settings.baudrate, settings.parity, settings.effective_stopbits)
    return (request_bytes + reply_bytes) * char_s + 2 * gap_s
