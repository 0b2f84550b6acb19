"""Link settings and checks that every transport shares (no pymodbus, no pyserial here)."""

from dataclasses import dataclass
import os

from drive_bridge.protocol import rtu
from drive_bridge.transport.protocols import PROTOCOLS

URL_PREFIXES = ('socket://', 'rfc2217://', 'loop://')


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


def port_missing(settings: LinkSettings) -> bool:
    """Return whether a serial device path does not exist (URLs are never missing)."""
    return settings.is_serial and not settings.port.startswith(URL_PREFIXES) and \
        not os.path.exists(settings.port)


def open_hint(settings: LinkSettings) -> str:
    """Return why a serial port may have failed to open, in words ('' if no idea)."""
    if settings.is_serial and not settings.port.startswith(URL_PREFIXES) and \
            not os.access(settings.port, os.R_OK | os.W_OK):
        return ' (permission denied: add the user to the dialout group)'
    if settings.is_serial and settings.parity != 'N' and '/pts/' in settings.port:
        return ' (a pty accepts parity N only)'
    return ''


def wire_time_s(settings: LinkSettings, request_bytes: int, reply_bytes: int) -> float:
    """Return the minimum time one RTU transaction occupies the line, gaps included."""
    char_s = rtu.character_time_s(settings.baudrate, settings.parity,
                                  settings.effective_stopbits)
    gap_s = rtu.frame_gap_s(settings.baudrate, settings.parity, settings.effective_stopbits)
    return (request_bytes + reply_bytes) * char_s + 2 * gap_s
