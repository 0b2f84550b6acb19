"""
Danfoss FC-protocol master on a serial port (pyserial), reading replies by their length.

One :class:`~drive_bridge.protocol.fc_telegram.FcTelegramRequest` is one telegram and one
reply: :meth:`FcProtocolTransport.execute` adds the address (format 1-126 by default, 1-31
if set), sends the telegram and reads the reply by its LGE with the pure decoder
(:func:`drive_bridge.protocol.fc_telegram.decode`, a "need more bytes" contract): it asks
the port for exactly the bytes still missing, so it returns the moment the last one
arrives. Every read, the local echo and the drain after a bad reply included, ends at the
one transaction deadline (``timeout_s`` after the request was written): a line that keeps
babbling cannot hold the bus longer than that.

Failures are the typed errors of :mod:`drive_bridge.errors`: silence is ``NoResponse``, a
reply cut short ``TruncatedFrame``, a bad BCC ``CrcError``, a valid telegram from another
address ``WrongAddress``, anything else (bad STX, impossible LGE, a reply that does not
answer the request) ``BadFrame``, and an AK 7 reply :class:`FcParameterError`, a
``DeviceException`` with the drive's error code and the reply (its status word is valid).
A broadcast (address 0) is sent without waiting: nobody answers it.
"""

import time
from typing import Callable, Optional

from drive_bridge.errors import (
    BadFrame, ConfigError, CrcError, DeviceException, NoResponse, TruncatedFrame, WrongAddress)
from drive_bridge.protocol import fc_telegram as fc
from drive_bridge.protocol.fc_telegram import FcTelegram, FcTelegramRequest
from drive_bridge.transport.link import LinkSettings
from drive_bridge.transport.serial_port import PORT_ERRORS, SerialPortTransport
import serial

DRAIN_SILENCE_S = 0.02  # USB adapters deliver bytes in ~16 ms batches (protocols.md)
_INVALID_REPLY = {fc.ERROR_BCC: CrcError, fc.ERROR_WRONG_ADDRESS: WrongAddress}


class FcParameterError(DeviceException):
    """An AK 7 reply: the drive could not perform the parameter command (code in PWElow)."""

    def __init__(self, code: int, reply: FcTelegram):
        super().__init__(code, f'parameter {reply.pnu}: {fc.explain_error(code)}', reply)


class FcProtocolTransport(SerialPortTransport):
    """Run FC-protocol transactions on one serial line (8E1 by default); the bus owns it."""

    def __init__(self, settings: LinkSettings,
                 address_format: str = fc.DEFAULT_ADDRESS_FORMAT,
                 open_port: Callable[..., object] = serial.serial_for_url):
        if address_format not in fc.ADDRESS_FORMATS:
            raise ConfigError(f'address_format {address_format!r}: allowed '
                              f'{", ".join(fc.ADDRESS_FORMATS)}')
        super().__init__(settings, open_port)
        self.address_format = address_format

    def execute(self, unit: int, request: FcTelegramRequest) -> Optional[FcTelegram]:
        """Send ``request`` to address ``unit``; return the reply (None for a broadcast)."""
        self._require_port()
        if not isinstance(request, FcTelegramRequest):
            raise TypeError(f'unsupported transaction {request!r}')
        telegram = request.telegram(unit, self.address_format)
        try:
            reply = self._exchange(telegram, request.max_reply_lge)
        except PORT_ERRORS as error:
            raise self._port_failed(error) from error
        if reply is None:
            return None
        problem = fc.reply_problem(request, reply)
        if problem:
            raise BadFrame(f'invalid reply ({problem})')
        if reply.is_error:
            raise FcParameterError(reply.error_code, reply)
        return reply

    def _exchange(self, telegram: FcTelegram, max_lge: int) -> Optional[FcTelegram]:
        port = self._port
        port.reset_input_buffer()  # a late reply to an earlier telegram must not count
        encoded = telegram.encode()
        deadline = time.monotonic() + self.settings.timeout_s
        self._write(encoded, deadline)
        if self.settings.local_echo:
            echo = self._read(len(encoded), deadline)
            if echo != encoded:
                self._drain(deadline, DRAIN_SILENCE_S)
                raise BadFrame('the adapter did not echo the telegram (local_echo is set)')
        if telegram.address.broadcast:
            return None
        return self._receive(telegram.adr, max_lge, deadline)

    def _receive(self, adr: int, max_lge: int, deadline: float) -> FcTelegram:
        buffer = b''
        wanted = fc.MIN_TELEGRAM_BYTES
        while True:
            chunk = self._read(wanted, deadline)
            buffer += chunk
            result = fc.decode(buffer, adr, max_lge)
            if result.telegram is not None:
                return result.telegram
            if result.error:
                self._drain(deadline, DRAIN_SILENCE_S)
                error_type = _INVALID_REPLY.get(result.error, BadFrame)
                raise error_type(f'invalid reply ({result.reason}), {len(buffer)} bytes '
                                 'received')
            if len(chunk) < wanted:  # the deadline passed
                if not buffer:
                    raise NoResponse(f'no reply within {self.settings.timeout_s:g} s')
                raise TruncatedFrame(f'truncated reply: {len(buffer)} of '
                                     f'{len(buffer) + result.missing} bytes within '
                                     f'{self.settings.timeout_s:g} s')
            wanted = result.missing
