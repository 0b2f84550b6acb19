"""
The transport registry: which transport carries each protocol, and :func:`make_transport`.

The protocol table (:mod:`drive_bridge.transport.protocols`) says what a protocol is: its
link, framing, request types and settings. The link settings read it, and every transport
reads the link settings, so the table cannot name the transports without an import cycle.
This registry sits above both: one factory per protocol, from the link settings and the
protocol's validated options (bus settings by name).
``test/unit/test_transport_registry.py`` checks that every protocol in the table has its
factory here and nothing else does.
"""

from typing import Any, Callable, Dict, Mapping, Optional

from drive_bridge.protocol import fc_telegram
from drive_bridge.transport.ap_ascii import ApAsciiTransport
from drive_bridge.transport.base import Transport
from drive_bridge.transport.fc_protocol import FcProtocolTransport
from drive_bridge.transport.link import LinkSettings
from drive_bridge.transport.serial_rtu import RtuSerialTransport
from drive_bridge.transport.wire_trace import TraceSettings

TransportFactory = Callable[[LinkSettings, Mapping[str, Any]], Transport]


def _modbus_rtu(link: LinkSettings, options: Mapping[str, Any]) -> Transport:
    """Modbus RTU on a serial port, or RTU frames over TCP: the native engine."""
    return RtuSerialTransport(link)


def _modbus_tcp(link: LinkSettings, options: Mapping[str, Any]) -> Transport:
    # Imported here: pymodbus costs every process that does not use it about 0.1 s of CPU
    # (each node start, each CLI command), and the serial engines do not.
    from drive_bridge.transport.modbus import ModbusTransport
    return ModbusTransport(link)


def _fc_protocol(link: LinkSettings, options: Mapping[str, Any]) -> Transport:
    return FcProtocolTransport(link, options.get('address_format', fc_telegram.ADDRESS_FORMAT_126))


def _ap_ascii(link: LinkSettings, options: Mapping[str, Any]) -> Transport:
    return ApAsciiTransport(link, options.get('ap_nak_retries', 2),
                            options.get('ap_address_lrc_eot', True))


TRANSPORTS: Dict[str, TransportFactory] = {
    'modbus_rtu': _modbus_rtu,
    'ap_ascii': _ap_ascii,
    'fc_protocol': _fc_protocol,
    'modbus_tcp': _modbus_tcp,
    'rtu_over_tcp': _modbus_rtu,
}


def make_transport(link: LinkSettings, options: Optional[Mapping[str, Any]] = None,
                   trace: Optional[TraceSettings] = None) -> Transport:
    """Return the transport of ``link`` with the protocol's ``options``, traced if asked."""
    transport = TRANSPORTS[link.protocol](link, options or {})
    if trace is not None and trace.enabled:
        transport.start_trace(trace)
    return transport
