"""
The protocol table: every bus protocol, its link, framing, request types and settings.

This is the one place that names the protocols. Configuration (which protocols exist, their
defaults and their own settings), the link settings (serial or TCP, framing), the node and
the tools all read it. It imports no transport (the transports read the link settings,
which read this table): which transport carries a protocol is the transport registry's
entry (:mod:`drive_bridge.transport.engines`). A new protocol is a codec in
:mod:`drive_bridge.protocol`, a transport module here, one entry in :data:`PROTOCOLS` and
its factory in ``engines.TRANSPORTS``.
"""

from dataclasses import dataclass
from typing import Any, Callable, Dict, Mapping, Optional, Tuple

from drive_bridge.protocol import ap_ascii, fc_telegram, rtu
from drive_bridge.protocol.requests import AP_ASCII_REQUESTS, MODBUS_REQUESTS
from drive_bridge.settings import Setting

SERIAL_ENGINES = ('native',)
PYMODBUS_RETIRED = ("pymodbus's serial client was removed after 0.4: it takes the first frame it "
                    'reads, a late reply too; remove serial_engine: the native engine keeps '
                    'the line discipline, see docs/reliability.md, "Late replies"')
# The quarantine's guard by protocol (late_reply_guard 0): how long after a failed transaction
# a late reply is still expected. The Modbus serial-line spec names no response time (its
# broadcast turnaround delay is 100-200 ms); the FC protocol's slowest documented reply
# comes 50 ms after the telegram (VLT 2800/8000), twice that is the guard; the MCD 3000 may
# take 250 ms to answer AP ASCII (protocols.md); a transparent gateway adds its buffering.
MODBUS_RTU_GUARD_S = 0.1
FC_PROTOCOL_GUARD_S = 2 * fc_telegram.MAX_REPLY_DELAY_S
AP_ASCII_GUARD_S = ap_ascii.MIN_TIMEOUT_S
RTU_OVER_TCP_GUARD_S = 0.2


@dataclass(frozen=True)
class ProtocolSpec:
    """
    One bus protocol.

    ``link``: 'serial' (a port) or 'tcp' (a gateway). ``fixed_framing``: (parity, stop bits)
    the protocol always uses, whatever is configured (AP ASCII: 8N1). ``default_stopbits``
    gives the stop bits for ``stopbits: 0`` from the parity; ``frame_gap_s`` the silence a
    master keeps between transactions (baud rate, parity, stop bits). ``settings``: the bus
    settings only this protocol takes.
    """

    name: str
    description: str
    link: str
    requests: Tuple[type, ...]
    fixed_framing: Optional[Tuple[str, int]] = None
    default_stopbits: Callable[[str], int] = rtu.default_stopbits
    frame_gap_s: Callable[[int, str, int], float] = rtu.frame_gap_s
    min_timeout_s: float = 0.02
    reply_guard_s: float = 0.0
    # One answered poll transaction, for the keepalive rule (drive_bridge.bus.keepalive):
    # request and reply characters at most, and how long a device may take to answer.
    poll_frame_chars: int = 30
    reply_delay_s: float = fc_telegram.MAX_REPLY_DELAY_S
    # Device addresses the protocol carries, from its options (None: the family's range).
    address_range: Optional[Callable[[Mapping[str, Any]], Tuple[int, int]]] = None
    settings: Tuple[Setting, ...] = ()

    @property
    def is_serial(self) -> bool:
        """Return whether the protocol runs on a local serial port."""
        return self.link == 'serial'


PROTOCOLS: Dict[str, ProtocolSpec] = {spec.name: spec for spec in (
    ProtocolSpec(
        'modbus_rtu', 'Modbus RTU on a serial port', 'serial', MODBUS_REQUESTS,
        reply_guard_s=MODBUS_RTU_GUARD_S,
        settings=(Setting('serial_engine', str, 'native',
                          'Modbus RTU on a serial port: native, the only engine after 0.4',
                          choices=SERIAL_ENGINES, retired=(('pymodbus', PYMODBUS_RETIRED),)),)),
    ProtocolSpec(
        'ap_ascii', 'MCD AP ASCII on a serial port (8N1)', 'serial', AP_ASCII_REQUESTS,
        fixed_framing=('N', 1), default_stopbits=lambda parity: 1,
        min_timeout_s=ap_ascii.MIN_TIMEOUT_S, reply_guard_s=AP_ASCII_GUARD_S,
        poll_frame_chars=40, reply_delay_s=ap_ascii.MIN_TIMEOUT_S,
        settings=(
            Setting('ap_nak_retries', int, 2,
                    'AP ASCII: how often an exchange answered with NAK (bad LRC, not '
                    'executed) is restarted from the address', low=0, high=10),
            Setting('ap_address_lrc_eot', bool, True,
                    'AP ASCII: the address fragment LRC includes EOT (the manual leaves it '
                    'open)'))),
    ProtocolSpec(
        'fc_protocol', 'the Danfoss FC protocol on a serial port (VLT 5000/6000 par. 500, '
        'FC 51 par. 8-30; 8E1 by default)', 'serial', (fc_telegram.FcTelegramRequest,),
        default_stopbits=lambda parity: fc_telegram.DEFAULT_STOPBITS,
        reply_guard_s=FC_PROTOCOL_GUARD_S, poll_frame_chars=32,
        frame_gap_s=lambda baudrate, parity, stopbits: fc_telegram.GAP_CHARACTERS *
        rtu.character_time_s(baudrate, parity, stopbits),
        address_range=lambda options: (1, 31) if options.get('address_format') ==
        fc_telegram.ADDRESS_FORMAT_31 else (1, 126),
        settings=(Setting('address_format', str, fc_telegram.ADDRESS_FORMAT_126,
                          'FC protocol: the address byte format the drives expect (1-126: '
                          'addresses 1-126, the FC series; 1-31: addresses 1-31)',
                          choices=fc_telegram.ADDRESS_FORMATS),)),
    ProtocolSpec('modbus_tcp', 'Modbus TCP gateway', 'tcp', MODBUS_REQUESTS,
                 frame_gap_s=lambda baudrate, parity, stopbits: 0.0),
    ProtocolSpec('rtu_over_tcp', 'transparent serial-to-Ethernet gateway (Modbus RTU frames)',
                 'tcp', MODBUS_REQUESTS, reply_guard_s=RTU_OVER_TCP_GUARD_S,
                 frame_gap_s=lambda baudrate, parity, stopbits: 0.0),
)}


def protocol_settings() -> Tuple[Setting, ...]:
    """Return every protocol's own bus settings (each name once)."""
    seen: Dict[str, Setting] = {}
    for spec in PROTOCOLS.values():
        for setting in spec.settings:
            seen.setdefault(setting.name, setting)
    return tuple(seen.values())
