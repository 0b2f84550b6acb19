"""
Late replies on pymodbus's serial line: the reply asked for, not the first frame read.

RTU has no transaction id. A device that answers request A only after the master gave up on
it answers A and then B, and both replies can arrive at once. pymodbus's RTU framer takes the
first frame in what it read (3.16 drops everything after it; 3.6 reads the first frame's
length and leaves the rest in the port): a late reply of the same unit and function is taken
for the one asked for (stale values), and a late reply of another unit makes it lose the
reply asked for (a write the device executed is answered as failed).

:class:`TappedSerialClient` keeps every byte pymodbus read in a transaction, and what is still
waiting after it; it changes what pymodbus reads only where pymodbus 3.6 would wait out the
timeout a second time for a reply that has not begun (see its ``recv``). :func:`settle` then
looks at them with the project's own RTU codec: when whole valid frames came back to back,
the last reply of the unit to the request's function is the newest (devices answer in order)
and is taken; otherwise pymodbus's outcome stands. On a clean line one frame and nothing
after it was read: nothing waits and pymodbus's outcome is returned as it is.
"""

import time
from typing import Any, Dict, Optional

from drive_bridge.errors import CrcError, DeviceException, TransportError, TruncatedFrame
from drive_bridge.protocol import rtu
from drive_bridge.protocol.requests import ModbusRequest
from drive_bridge.transport.serial_port import PORT_ERRORS
from pymodbus.client import ModbusSerialClient

POLL_INTERVAL_S = 0.0005  # while the rest of a begun reply is awaited (rare: see settle)


class TappedSerialClient(ModbusSerialClient):
    """pymodbus's serial client that keeps the bytes of each transaction (``received``)."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.received = bytearray()  # read by pymodbus in this transaction, and left after it
        self.bytes_before_send = False  # bytes waited in the port when the request went out
        self._in_transaction = False

    def execute(self, *args, **kwargs):
        """Run pymodbus's transaction (3.6: request; 3.16: no_response_expected, request)."""
        self.received.clear()
        self.bytes_before_send = False
        self._in_transaction = True
        try:
            return super().execute(*args, **kwargs)
        finally:
            self._keep_waiting()
            self._in_transaction = False

    def send(self, *args, **kwargs) -> int:
        """Note bytes that pymodbus drops before the request (they came after the last one)."""
        if self._in_transaction and self._waiting():
            self.bytes_before_send = True
        return super().send(*args, **kwargs)

    def recv(self, size):
        """
        Read as pymodbus asks, keeping a copy; return nothing once the timeout passed silent.

        pymodbus 3.6 asks for a size, waits up to the timeout for a reply's first bytes and
        then reads them with the port's own timeout, so a silent address cost twice the
        timeout (0.6 s at 0.3 s). Here the read follows the first wait only when that wait
        saw bytes. pymodbus 3.16 asks for no size (``None``) and reads as it did.
        """
        if self.socket is not None and size is not None and size > self._waiting():
            if not self._wait_for_data() and not self._waiting():
                return b''  # nothing within the timeout: pymodbus reports no response
            data = self.socket.read(size)
        else:
            data = super().recv(size)
        if self._in_transaction and data:
            self.received += data
        return data

    def close(self):
        """Close the port; pymodbus 3.6 does so after a reply it cannot decode: keep the rest."""
        if self._in_transaction:
            self._keep_waiting()
        super().close()

    def _waiting(self) -> int:
        try:
            return self.socket.in_waiting if self.socket is not None else 0
        except PORT_ERRORS:
            return 0

    def _keep_waiting(self) -> None:
        """Add the bytes waiting in the port now to ``received`` (no wait)."""
        waiting = self._waiting()
        if waiting:
            try:
                self.received += self.socket.read(waiting)
            except PORT_ERRORS:
                pass

    def read_until(self, length: int, deadline: float) -> bool:
        """Read until ``received`` holds ``length`` bytes or the deadline passes; say which."""
        while len(self.received) < length:
            self._keep_waiting()
            if len(self.received) >= length or time.monotonic() >= deadline or \
                    self.socket is None:
                break
            time.sleep(POLL_INTERVAL_S)
        return len(self.received) >= length


def _newest(client: TappedSerialClient, unit: int, function: int,
            deadline: float) -> Optional[rtu.NewestReply]:
    """Return the newest reply in what was received (None: one frame and nothing after it)."""
    received = bytes(client.received)
    length = rtu.response_length(received)
    if length is not None and len(received) <= length:
        return None  # the clean path: one reply (or part of one), nothing after it
    newest = rtu.newest_reply(received, unit, function)
    while newest.needed and client.read_until(newest.needed, deadline):
        newest = rtu.newest_reply(bytes(client.received), unit, function)
    return newest


def settle(client: TappedSerialClient, unit: int, request: ModbusRequest, deadline: float,
           outcome: Any, failure: Optional[TransportError], recovered: Dict[str, int]) -> Any:
    """
    Return the transaction's result or raise its error: pymodbus's, or the newest reply's.

    ``outcome``/``failure``: what pymodbus made of the transaction. When two or more whole
    valid frames were received back to back, the last reply of ``unit`` to the request is
    taken and the other frames count as late replies in ``recovered``. When a reply of the
    unit began after the frame pymodbus took and was not whole by ``deadline``, or had a CRC
    error, pymodbus's reply may be the late one: the transaction fails.
    """
    if client.bytes_before_send:
        recovered['late_bytes'] = 1
    frame = request.frame(unit)
    newest = _newest(client, unit, frame.function, deadline)
    if newest is not None and failure is None and (newest.needed or newest.spoiled):
        error_type = CrcError if newest.spoiled else TruncatedFrame
        raise error_type('a second reply began after the reply and was not whole and valid '
                         f'within the timeout ({len(client.received)} bytes; the first may be '
                         'a late one)')
    if newest is None or newest.frames < 2 or newest.frame is None:
        if failure is not None:
            raise failure
        return outcome
    recovered['late_reply'] = newest.frames - 1
    if newest.frame.function & 0x80:
        raise DeviceException(newest.frame.data[0])
    return request.parse(frame, newest.frame)
