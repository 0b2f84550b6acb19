"""
AP ASCII master on a serial port (pyserial, 8N1): the exchanges of :mod:`..protocol.ap_ascii`.

One transaction is address -> ACK -> command -> ACK, or address -> ACK -> request -> reply.
A NAK (the slave saw a bad LRC, so it did not act) restarts the exchange from the address
fragment, at most ``nak_retries`` times; a BEL (refused) is a DeviceException with code 7;
silence is NoResponse (an unknown address never answers); anything else is BadFrame.
"""

import time
from typing import Callable, Optional

from drive_bridge.errors import BadFrame, DeviceException, NoResponse
from drive_bridge.protocol import ap_ascii
from drive_bridge.protocol.requests import AsciiCommand, AsciiRequest
from drive_bridge.transport.link import LinkSettings
from drive_bridge.transport.serial_port import PORT_ERRORS, SerialPortTransport
import serial

DRAIN_SILENCE_S = 0.02  # USB adapters deliver bytes in ~16 ms batches


class Nak(BadFrame):
    """The slave answered NAK: it saw a bad LRC and did not act on the fragment."""

    kind = 'nak'


class ApAsciiTransport(SerialPortTransport):
    """Run AP ASCII transactions on one serial line (8N1); the bus thread owns it."""

    def __init__(self, settings: LinkSettings, nak_retries: int = 2,
                 address_lrc_includes_eot: bool = True,
                 open_port: Callable[..., object] = serial.serial_for_url):
        super().__init__(settings, open_port)
        self.nak_retries = nak_retries
        self.address_lrc_includes_eot = address_lrc_includes_eot
        self.naks = 0  # NAKs seen (each one retried or reported)
        self._reply_deadline = 0.0  # when the reply being read is late

    def execute(self, unit: int, transaction) -> Optional[int]:
        """Run one transaction; return the status byte or data value of a request."""
        self._require_port()
        if not isinstance(transaction, (AsciiCommand, AsciiRequest)):
            raise TypeError(f'unsupported transaction {transaction!r}')
        try:
            return self._with_nak_retries(unit, transaction)
        except PORT_ERRORS as error:
            raise self._port_failed(error) from error

    def _with_nak_retries(self, unit: int, transaction) -> Optional[int]:
        attempt = 0
        self.last_recovered = {}
        while True:
            try:
                return self._exchange(unit, transaction)
            except Nak as error:
                self.naks += 1
                if attempt >= self.nak_retries:
                    raise Nak(f'{error} ({attempt + 1} attempts)') from None
                attempt += 1
                self.last_recovered = {'nak': attempt}

    def _exchange(self, unit: int, transaction) -> Optional[int]:
        # Reported sent once, with the address fragment: the bus's work then overlaps the
        # slave's answer to it (up to 250 ms), also when the address is dead.
        self._send(ap_ascii.address_fragment(unit, self.address_lrc_includes_eot))
        self._expect_ack('address')
        self._send(ap_ascii.message_fragment(transaction.code), report=False)
        if isinstance(transaction, AsciiCommand):
            self._expect_ack(transaction.code)
            return None
        reply = self._receive()
        if reply.kind != 'frame':
            self._refused_or_bad(reply, transaction.code)
        try:
            if transaction.reply == 'status':
                return ap_ascii.decode_status(reply.digits)
            return ap_ascii.decode_data(reply.digits)
        except ValueError as error:
            raise BadFrame(f'invalid reply to {transaction.code}: {error}') from None

    def _send(self, fragment: bytes, report: bool = True) -> None:
        self._port.reset_input_buffer()
        self._write(fragment, time.monotonic() + self.settings.timeout_s, report)

    def _expect_ack(self, what: str) -> None:
        reply = self._receive()
        if reply.kind != 'ACK':
            self._refused_or_bad(reply, what)

    def _refused_or_bad(self, reply: ap_ascii.Reply, what: str) -> None:
        # A slave answers with one fragment and falls silent: drop whatever follows an
        # unexpected answer, and a line that keeps talking is babbling (LineBabble).
        self._drain(self._reply_deadline, DRAIN_SILENCE_S)
        if reply.kind == 'NAK':
            raise Nak(f'NAK to {what}: the device saw a bad LRC')
        if reply.kind == 'BEL':
            raise DeviceException(ap_ascii.BEL, f'{what} refused (BEL)')
        if reply.kind == 'error':
            raise BadFrame(f'invalid reply to {what}: {reply.error}')
        raise BadFrame(f'unexpected {reply.kind} to {what}')

    def _receive(self) -> ap_ascii.Reply:
        deadline = self._reply_deadline = time.monotonic() + self.settings.timeout_s
        buffer = b''
        while True:
            reply = ap_ascii.decode_reply(buffer)
            if reply.kind:
                return reply
            chunk = self._read(reply.needed - len(buffer), deadline)
            if not chunk:
                if not buffer:
                    raise NoResponse(f'no reply within {self.settings.timeout_s:g} s')
                raise BadFrame(f'truncated reply: {len(buffer)} bytes')
            buffer += chunk
