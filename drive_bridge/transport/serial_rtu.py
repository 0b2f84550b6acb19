"""
Modbus RTU master on a serial port, or on a TCP stream of RTU frames (``rtu_over_tcp``).

The request is built by :mod:`drive_bridge.protocol.requests`; the reply is read by the line
discipline (:mod:`.exchange`) with the RTU framer, whose "need more bytes" answers let the
port wait for exactly the bytes still missing (no inter-character polling). A frame of the
unit is the answer only if it carries the request's function and fits the request (the
register count of a read, the echo of a write): anything else of the unit is a late reply to
an earlier request. An exception reply is a DeviceException with its code. This is the only
engine of ``protocol: modbus_rtu`` and of ``rtu_over_tcp``; Modbus TCP, whose replies carry
a transaction id, keeps pymodbus (:mod:`.modbus`).
"""

from dataclasses import dataclass
from typing import Any

from drive_bridge.errors import BadFrame, DeviceException
from drive_bridge.protocol import rtu
from drive_bridge.protocol.framing import Frame
from drive_bridge.protocol.requests import ModbusRequest
from drive_bridge.protocol.rtu import RtuFrame
from drive_bridge.transport.line_transport import LineTransport


@dataclass(frozen=True)
class _Refusal:
    """An exception reply: the device did not execute the request (its code)."""

    code: int


def accept_reply(request: ModbusRequest, sent: RtuFrame, received: Frame) -> Any:
    """Return what ``received`` carries if it answers ``sent``, else raise BadFrame."""
    reply = rtu.reply_frame(received)
    if reply.function & 0x7F != sent.function:
        raise BadFrame(f'reply with function {reply.function:02X}h to a {sent.function:02X}h '
                       'request')
    if reply.function & 0x80:
        return _Refusal(reply.data[0])
    return request.parse(sent, reply)


def shaped_like(sent: RtuFrame, received: Frame) -> bool:
    """Return whether a corrupt or cut frame has the shape of the answer: unit, function."""
    raw = received.raw
    return len(raw) < 2 or (raw[0] == sent.unit and raw[1] & 0x7F == sent.function)


class RtuSerialTransport(LineTransport):
    """Run single Modbus RTU transactions on one line; the bus thread owns it."""

    framer = rtu.ReplyFramer()
    requests = (ModbusRequest,)

    def _run(self, unit: int, request: ModbusRequest) -> Any:
        """Send ``request`` to ``unit``; return the registers or coils read, or None."""
        sent = request.frame(unit)
        value = self.discipline.exchange(
            sent.encode(), lambda received: accept_reply(request, sent, received),
            lambda received: shaped_like(sent, received), request.writes)
        if isinstance(value, _Refusal):
            raise DeviceException(value.code)
        return value
