"""
Danfoss FC-protocol master on a serial port (pyserial), reading replies by their length.

One :class:`~drive_bridge.protocol.fc_telegram.FcTelegramRequest` is one telegram and one
reply: :meth:`FcProtocolTransport.execute` adds the address (format 1-126 by default, 1-31
if set), sends the telegram and reads the reply by its LGE
through the line discipline (:mod:`.exchange`) with the FC framer
(:class:`drive_bridge.protocol.fc_telegram.ReplyFramer`): the port waits for exactly the
bytes still missing. A telegram of the address is the answer only if it has the telegram's
ADR byte and fits the request (a parameter reply for its PNU and AK, a process reply to a
process telegram): anything else is a late reply. Process telegrams echo nothing, so a late
one is told only by the discipline's rules (quarantine, one frame per window).

Failures are the typed errors of :mod:`drive_bridge.errors`: silence is ``NoResponse``, a
reply cut short ``TruncatedFrame``, a bad BCC ``CrcError``, telegrams from other addresses
only ``WrongAddress``, a telegram that does not answer the request ``MismatchedReply``, two
of the address in one window ``AmbiguousReply``, anything else (bad STX, impossible LGE)
``BadFrame``, and an AK 7 reply :class:`FcProtocolParameterError`, a ``DeviceException`` with the
drive's error code and the reply (its status word is valid). A broadcast (address 0) is
sent without waiting: nobody answers it.
"""

from typing import Callable, Optional

from drive_bridge.errors import BadFrame, ConfigError, DeviceException
from drive_bridge.protocol import fc_telegram
from drive_bridge.protocol.fc_telegram import FcTelegram, FcTelegramRequest
from drive_bridge.protocol.framing import Frame
from drive_bridge.transport.line_transport import LineTransport
from drive_bridge.transport.link import LinkSettings
import serial


class FcProtocolParameterError(DeviceException):
    """An AK 7 reply: the drive could not perform the parameter command (code in PWElow)."""

    def __init__(self, code: int, reply: FcTelegram):
        super().__init__(code, f'parameter {reply.pnu}: {fc_telegram.explain_error(code)}', reply)


def accept_telegram(request: FcTelegramRequest, sent: FcTelegram, received: Frame) -> FcTelegram:
    """Return ``received`` as a telegram if it answers ``sent``, else raise BadFrame."""
    if received.raw[2] != sent.adr:
        raise BadFrame(f'reply with ADR {received.raw[2]:02X}h to a telegram to ADR '
                       f'{sent.adr:02X}h')
    if received.raw[1] > request.max_reply_lge:
        raise BadFrame(f'reply with LGE {received.raw[1]} to a telegram whose reply has at '
                       f'most {request.max_reply_lge}')
    reply = fc_telegram.decode(received.raw).telegram
    problem = fc_telegram.reply_problem(request, reply)
    if problem:
        raise BadFrame(problem)
    return reply


class FcProtocolTransport(LineTransport):
    """Run FC-protocol transactions on one line (8E1 by default); the bus owns it."""

    framer = fc_telegram.ReplyFramer()
    requests = (FcTelegramRequest,)

    def __init__(self, settings: LinkSettings,
                 address_format: str = fc_telegram.DEFAULT_ADDRESS_FORMAT,
                 open_port: Callable[..., object] = serial.serial_for_url,
                 **line_options):
        if address_format not in fc_telegram.ADDRESS_FORMATS:
            raise ConfigError(f'address_format {address_format!r}: allowed '
                              f'{", ".join(fc_telegram.ADDRESS_FORMATS)}')
        super().__init__(settings, open_port, **line_options)
        self.address_format = address_format

    def _run(self, unit: int, request: FcTelegramRequest) -> Optional[FcTelegram]:
        """Send ``request`` to address ``unit``; return the reply (None for a broadcast)."""
        telegram = request.telegram(unit, self.address_format)
        if telegram.address.broadcast:
            self.discipline.send_only(telegram.encode())
            return None
        reply = self.discipline.exchange(
            telegram.encode(), lambda received: accept_telegram(request, telegram, received),
            lambda received: len(received.raw) < 3 or received.raw[2] == telegram.adr,
            request.writes)
        if reply.is_error:
            raise FcProtocolParameterError(reply.error_code, reply)
        return reply
