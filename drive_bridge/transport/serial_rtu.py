"""
Modbus RTU master on a serial port through pyserial, reading replies by their expected length.

The reply's length follows from its first bytes (:func:`drive_bridge.protocol.rtu.decode_response`,
a pure decoder with a "need more bytes" contract), so the transport asks the port for exactly
the bytes still missing and returns the moment the last one arrives: no inter-character
polling, no end-of-frame guessing (as libmodbus does). This is the default engine for
``protocol: modbus_rtu``; ``serial_engine: pymodbus`` selects pymodbus's serial client instead.
Failures are the typed errors of :mod:`drive_bridge.errors`.
"""

import functools
import time
from typing import Any, Tuple

from drive_bridge.errors import (
    BadFrame, CrcError, DeviceException, NoResponse, TruncatedFrame, WrongAddress)
from drive_bridge.protocol import rtu
from drive_bridge.protocol.requests import ModbusRequest
from drive_bridge.protocol.rtu import RtuFrame
from drive_bridge.transport.serial_port import PORT_ERRORS, SerialPortTransport


_INVALID_REPLY = {'crc': CrcError, 'wrong_address': WrongAddress}
_NOT_OURS = ('wrong_address', 'bad_frame')  # decode errors a late reply can cause


class RtuSerialTransport(SerialPortTransport):
    """Run single Modbus RTU transactions on a serial port; the bus thread owns it."""

    def execute(self, unit: int, request: ModbusRequest) -> Any:
        """Run one request with device ``unit``; return registers or coils read, or None."""
        self._require_port()
        if not isinstance(request, ModbusRequest):
            raise TypeError(f'unsupported request {request!r}')
        frame = request.frame(unit)
        self.last_recovered = {}
        try:
            reply = self._exchange(request, frame)
        except PORT_ERRORS as error:
            raise self._port_failed(error) from error
        if reply.function & 0x80:
            raise DeviceException(reply.data[0])
        return request.parse(frame, reply)

    def _exchange(self, request: ModbusRequest, frame: RtuFrame) -> RtuFrame:
        port = self._port
        if port.in_waiting:  # bytes that came after the last transaction ended
            self._count_recovered('late_bytes')
        port.reset_input_buffer()  # a late reply to an earlier request must not count
        encoded = frame.encode()
        deadline = time.monotonic() + self.settings.timeout_s
        self._write(encoded, deadline)
        if self.settings.local_echo:
            echo = self._read(len(encoded), deadline)
            if echo != encoded:
                raise BadFrame('the adapter did not echo the request (local_echo is set)')
        return self._receive(frame.unit, frame.function, request.reply_length(), deadline)

    def _receive(self, unit: int, function: int, expected: int, deadline: float) -> RtuFrame:
        """
        Read the reply by its length: wait for its first bytes, then for the rest.

        At most two wake-ups, whatever the baud rate or the adapter's batching. On a local
        port (VMIN): when the shortest reply's 5 bytes are there (an exception reply is then
        whole), and, unless the rest came with them (read without a wait), when the bytes the
        decoder says are missing are there. Elsewhere: the first byte, and the wire time of
        the ``expected`` bytes. Then the decoder says what is missing, if anything.
        """
        # Up to 5 bytes only: whatever follows a 5-byte exception reply is not part of it.
        buffer = self._read_some(rtu.MIN_RESPONSE_BYTES, deadline - time.monotonic(),
                                 at_least=rtu.MIN_RESPONSE_BYTES)
        if not buffer:
            raise NoResponse(f'no reply within {self.settings.timeout_s:g} s')
        self._await_bytes(expected - len(buffer), self._char_s, deadline)
        awaited = expected  # bytes whose wire time was waited for since the first one
        needed = rtu.MIN_RESPONSE_BYTES
        while True:
            buffer += self._read(needed - len(buffer), deadline)
            result = rtu.decode_response(buffer, unit, function)
            if result.frame is not None:
                return self._newest_reply(result.frame, unit, function, deadline)
            if result.error_kind in _NOT_OURS:
                not_ours = result
                skipped, buffer = self._skip_late_reply(buffer, deadline)
                if skipped:
                    if not buffer:
                        buffer = self._read_some(1, deadline - time.monotonic())
                    if not buffer:  # it was not a late reply but the answer: a wrong one
                        error_type = _INVALID_REPLY.get(not_ours.error_kind, BadFrame)
                        raise error_type(f'invalid reply ({not_ours.error}) and no other '
                                         f'within {self.settings.timeout_s:g} s')
                    self._count_recovered('late_reply')
                    needed, awaited = rtu.MIN_RESPONSE_BYTES, 0
                    continue
                result = rtu.decode_response(buffer, unit, function)
            if result.error:
                self._drain(deadline, self._silence_s)
                error_type = _INVALID_REPLY.get(result.error_kind, BadFrame)
                raise error_type(f'invalid reply ({result.error}), {len(buffer)} bytes '
                                 'received')
            if len(buffer) < needed:  # the deadline passed
                length = rtu.response_length(buffer)
                got = f'{len(buffer)} of {length} bytes' if length else \
                    f'{len(buffer)} byte{"s" * (len(buffer) > 1)}, too few to tell its length,'
                raise TruncatedFrame(f'truncated reply: {got} within '
                                     f'{self.settings.timeout_s:g} s')
            needed = result.needed
            if needed > awaited:  # not slept for yet (a second sleep would wake late)
                self._await_bytes(needed - len(buffer), self._char_s, deadline)
                awaited = needed

    def _newest_reply(self, reply: RtuFrame, unit: int, function: int,
                      deadline: float) -> RtuFrame:
        """
        Return ``reply``, or a newer reply of ``unit`` to ``function`` that came right after it.

        RTU has no transaction id: a device that answered an earlier request late answers it
        and then this one, and both replies can arrive at once. Devices answer in order, so of
        whole valid replies waiting back to back the last one is the newest and is taken; the
        others count as late replies. Only bytes already there are looked at (no wait on a
        clean line, where nothing follows a reply); a reply of the unit to the function that
        has begun is waited for (up to the deadline). If it does not complete, or its CRC is
        wrong, the transaction fails: ``reply`` may be the late one. Bytes that begin no such
        reply (a stray byte) leave ``reply`` as it is.
        """
        tail = self._read_some(rtu.MAX_ADU_BYTES, 0.0)
        if not tail:
            return reply
        newest = rtu.newest_reply(tail, unit, function)
        while newest.needed:
            tail += self._read(newest.needed - len(tail), deadline)
            if len(tail) < newest.needed:
                raise TruncatedFrame(f'a second reply began after the reply and was not whole '
                                     f'within {self.settings.timeout_s:g} s (the first may be '
                                     'a late one)')
            newest = rtu.newest_reply(tail, unit, function)
        if newest.spoiled:
            raise CrcError('a second reply with a CRC error came after the reply (the first '
                           'may be a late one)')
        self._count_recovered('late_reply', newest.frames)
        return newest.frame or reply

    def _count_recovered(self, kind: str, count: int = 1) -> None:
        """Count ``count`` failures of ``kind`` the transaction recovered from."""
        if count:
            self.last_recovered[kind] = self.last_recovered.get(kind, 0) + count

    def _skip_late_reply(self, buffer: bytes, deadline: float) -> Tuple[bool, bytes]:
        """
        Drop a whole, valid frame that is not the reply asked for.

        Such a frame is a late reply to an earlier request (to this device or another) that
        came after its own transaction gave up; the reply asked for may follow it.

        Return (whether one was dropped, the bytes after it, or all bytes read if not).
        """
        while True:
            length = rtu.response_length(buffer)
            if length is None and len(buffer) >= 3:
                return False, buffer  # no function a device answers with: garbage
            wanted = (length or 3) - len(buffer)
            if wanted <= 0:
                break
            chunk = self._read(wanted, deadline)
            buffer += chunk
            if len(chunk) < wanted:
                return False, buffer
        if not rtu.crc_ok(buffer[:length]):
            return False, buffer
        return True, buffer[length:]

    @functools.cached_property
    def _char_s(self) -> float:
        return rtu.character_time_s(self.settings.baudrate, self.settings.effective_parity,
                                    self.settings.effective_stopbits)

    @functools.cached_property
    def _silence_s(self) -> float:
        """Return the pause that ends a frame (3.5 characters)."""
        return rtu.frame_gap_s(self.settings.baudrate, self.settings.parity,
                               self.settings.effective_stopbits)
