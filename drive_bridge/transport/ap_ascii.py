"""
AP ASCII master on a serial port (pyserial, 8N1): the exchanges of :mod:`..protocol.ap_ascii`.

One transaction is address -> ACK -> command -> ACK, or address -> ACK -> request -> reply.
A NAK (the slave saw a bad LRC, so it did not act) restarts the exchange from the address
fragment, at most ``nak_retries`` times; a BEL (refused) is a DeviceException with code 7;
silence is NoResponse (an unknown address never answers); anything else is BadFrame.

Every fragment goes out and every answer is read through the line discipline
(:mod:`.exchange`) with the AP ASCII framer. No AP ASCII reply names its slave, so an ACK
that came late cannot be told from the ACK asked for by its bytes: after a transaction that
ends badly the line is quarantined (the guard defaults to the MCD 3000's 250 ms response
time), and while any exchange may still owe its answer the next transaction's first window
stays open to its deadline: two answers in it fail the transaction (a command is then
unanswered: a start may be running, a stop is not done).
"""

from typing import Callable, Optional, Tuple

from drive_bridge.errors import BadFrame, DeviceException, Nak
from drive_bridge.protocol import ap_ascii
from drive_bridge.protocol.framing import Frame
from drive_bridge.protocol.requests import AsciiCommand, AsciiRequest
from drive_bridge.transport.line_transport import LineTransport
from drive_bridge.transport.link import LinkSettings
import serial

ANSWERS = ('ACK', 'NAK', 'BEL')  # a slave's answers to an address or a command
DATA_ANSWERS = ('frame', 'NAK', 'BEL')  # its answers to a request


def accepting(kinds: Tuple[str, ...], what: str) -> Callable[[Frame], Frame]:
    """Return an ``accept`` that takes a reply of ``kinds`` to ``what``, else BadFrame."""
    def accept(frame: Frame) -> Frame:
        kind = ap_ascii.reply_kind(frame)
        if kind not in kinds:
            shown = 'a data reply' if kind == 'frame' else kind
            raise BadFrame(f'{shown} to {what}')
        return frame
    return accept


class ApAsciiTransport(LineTransport):
    """Run AP ASCII transactions on one serial line (8N1); the bus thread owns it."""

    framer = ap_ascii.ReplyFramer()
    requests = (AsciiCommand, AsciiRequest)

    def __init__(self, settings: LinkSettings, nak_retries: int = 2,
                 address_lrc_includes_eot: bool = True,
                 open_port: Callable[..., object] = serial.serial_for_url,
                 **line_options):
        super().__init__(settings, open_port, **line_options)
        self.nak_retries = nak_retries
        self.address_lrc_includes_eot = address_lrc_includes_eot
        self.naks = 0  # NAKs seen (each one retried or reported)

    def _run(self, unit: int, transaction) -> Optional[int]:
        """Run one transaction, again from the address after a NAK; see the module."""
        attempt = 0
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
        discipline = self.discipline
        address = ap_ascii.address_fragment(unit, self.address_lrc_includes_eot)
        _answered(discipline.exchange(address, accepting(ANSWERS, 'the address')), 'address')
        message = ap_ascii.message_fragment(transaction.code)
        if isinstance(transaction, AsciiCommand):
            reply = discipline.exchange(message, accepting(ANSWERS, transaction.code))
            _answered(reply, transaction.code)
            return None
        reply = discipline.exchange(message, accepting(DATA_ANSWERS, transaction.code))
        _answered(reply, transaction.code)
        digits = reply.raw[1:5]
        try:
            if transaction.reply == 'status':
                return ap_ascii.decode_status(digits)
            return ap_ascii.decode_data(digits)
        except ValueError as error:
            raise BadFrame(f'invalid reply to {transaction.code}: {error}') from None


def _answered(reply: Frame, what: str) -> None:
    """Return if ``reply`` is an ACK or data; raise Nak, or DeviceException for a BEL."""
    kind = ap_ascii.reply_kind(reply)
    if kind == 'NAK':
        raise Nak(f'NAK to {what}: the device saw a bad LRC')
    if kind == 'BEL':
        raise DeviceException(ap_ascii.BEL, f'{what} refused (BEL)')
