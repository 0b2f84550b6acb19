"""
A serial port opened to look at the line itself, not to talk to a device: ``drive-bridge doctor``.

:class:`PortProbe` listens (is the line quiet, or does something babble?) and sends a few
bytes that no device takes for a request, then listens for them coming back (does the
adapter echo what it sends?). It reads and writes through the transports' own port
(:class:`~drive_bridge.transport.serial_port.SerialLine`): opened exclusively, with the
same refusals in words.
"""

import time
from typing import Optional

from drive_bridge.transport.link import LinkSettings
from drive_bridge.transport.serial_port import SerialLine

# Bytes no device on the line acts on: address 255 (no Modbus unit), no STX (FC protocol),
# no EOT (AP ASCII), and no valid CRC whatever is read as a frame.
PROBE_BYTES = bytes([0xFF, 0xA5, 0x5A, 0xC3, 0x3C, 0xFF])
READ_CHUNK = 4096


class PortProbe:
    """One serial port, open for listening and for the echo test (a context manager)."""

    def __init__(self, settings: LinkSettings):
        self.settings = settings
        self._line: Optional[SerialLine] = None

    def __enter__(self) -> 'PortProbe':
        """Open the port; raise LinkDown with the reason in words."""
        self._line = SerialLine(self.settings, self.settings.port)
        self._line.connect()
        return self

    def __exit__(self, *exc) -> None:
        """Close the port."""
        if self._line is not None:
            self._line.close()
            self._line = None

    def listen(self, seconds: float) -> bytes:
        """Return every byte that arrives within ``seconds`` (b'': the line kept quiet)."""
        received = bytearray()
        deadline = time.monotonic() + seconds
        while True:
            left_s = deadline - time.monotonic()
            if left_s <= 0:
                return bytes(received)
            received += self._line.read(READ_CHUNK, left_s, READ_CHUNK)

    def send_and_listen(self, data: bytes, seconds: float) -> bytes:
        """Send ``data``, then return every byte that arrives within ``seconds``."""
        self._line.read(READ_CHUNK, 0.0)  # what came before is no answer to this
        self._line.write(data, time.monotonic() + seconds)
        return self.listen(seconds)
