"""
pcapng blocks for wire traces that Wireshark opens: bytes out, no I/O, no clock. Pure.

The layout (pcapng, IETF draft-ietf-opsawg-pcapng; tried with tshark 4.0, see
``docs/wire_trace.md``): one Section Header Block, one Interface Description Block per line
(``if_name`` = the port, ``if_tsresol`` = 9: nanoseconds) of link type
``LINKTYPE_WIRESHARK_UPPER_PDU`` (252), and one Enhanced Packet Block per frame. Each packet
starts with Wireshark's "exported PDU" tag list, which names the dissector that decodes it:
``mbrtu`` (Modbus RTU) and ``mbtcp`` (Modbus TCP, with the TCP port tags, so that query and
response are told apart) are Wireshark's own; the FC protocol and AP ASCII are decoded by the
Lua dissectors shipped with the package (:data:`DISSECTORS`, ``drive_bridge/wireshark/``). An
LVSG image travels in plain Modbus frames (RTU or TCP, as the gateway speaks): the shipped
postdissector ``danfoss_lvsg`` adds its bytes and bits to them, configured by a preference
naming each slave's registers (``docs/wireshark.md``). The
direction is the packet's ``epb_flags`` (inbound/outbound, shown as ``frame.p2p_dir``); the
comment (``frame.comment``) carries the transaction's outcome and the frame's end time.

Why hand-written: no maintained Python library writes pcapng with per-packet flags and
comments and the upper-PDU link type (python-pcapng is unmaintained, scapy is a large
dependency for 60 lines of struct packing).
"""

import struct
from typing import Iterable, Optional, Tuple

LINKTYPE_WIRESHARK_UPPER_PDU = 252
SNAPLEN = 0  # no limit
BYTE_ORDER_MAGIC = 0x1A2B3C4D

# Block types.
SECTION_HEADER = 0x0A0D0D0A
INTERFACE_DESCRIPTION = 0x00000001
ENHANCED_PACKET = 0x00000006

# Option codes.
OPT_END = 0
OPT_COMMENT = 1
SHB_USERAPPL = 4
IF_NAME = 2
IF_DESCRIPTION = 3
IF_TSRESOL = 9
EPB_FLAGS = 2

# epb_flags bits 0-1: the direction.
INBOUND = 1
OUTBOUND = 2

# Exported-PDU tags (Wireshark's epan/exported_pdu.h).
EXP_PDU_TAG_END = 0
EXP_PDU_TAG_DISSECTOR_NAME = 12
EXP_PDU_TAG_PORT_TYPE = 24
EXP_PDU_TAG_SRC_PORT = 25
EXP_PDU_TAG_DST_PORT = 26
PORT_TYPE_TCP = 2

# The dissector of each wire protocol's frames (the Lua ones ship in share/.../wireshark/).
# No entry for LVSG: its frames are Modbus frames (the postdissector danfoss_lvsg decodes the
# image in them).
DISSECTORS = {
    'modbus_rtu': 'mbrtu',
    'modbus_tcp': 'mbtcp',
    'fc_protocol': 'danfoss_fc',
    'ap_ascii': 'danfoss_ap_ascii',
}


def _pad4(data: bytes) -> bytes:
    """Return ``data`` padded with zero bytes to a multiple of 4."""
    return data + bytes(-len(data) % 4)


def _options(options: Iterable[Tuple[int, bytes]]) -> bytes:
    """Return the options (code, value) encoded, with opt_endofopt, or b'' if none."""
    encoded = b''.join(struct.pack('<HH', code, len(value)) + _pad4(value)
                       for code, value in options)
    return encoded + struct.pack('<HH', OPT_END, 0) if encoded else b''


def _block(block_type: int, body: bytes) -> bytes:
    """Return a block: type, total length, body (padded), total length again."""
    body = _pad4(body)
    total = len(body) + 12
    return struct.pack('<II', block_type, total) + body + struct.pack('<I', total)


def section_header(application: str = 'drive_bridge') -> bytes:
    """Return a Section Header Block (version 1.0, section length unknown)."""
    body = struct.pack('<IHHq', BYTE_ORDER_MAGIC, 1, 0, -1)
    return _block(SECTION_HEADER, body + _options([(SHB_USERAPPL, application.encode())]))


def interface_description(name: str, description: str = '',
                          link_type: int = LINKTYPE_WIRESHARK_UPPER_PDU) -> bytes:
    """Return an Interface Description Block with nanosecond timestamps."""
    options = [(IF_NAME, name.encode()), (IF_TSRESOL, bytes([9]))]
    if description:
        options.append((IF_DESCRIPTION, description.encode()))
    body = struct.pack('<HHI', link_type, 0, SNAPLEN)
    return _block(INTERFACE_DESCRIPTION, body + _options(options))


def exported_pdu(dissector: str, payload: bytes,
                 tcp_ports: Optional[Tuple[int, int]] = None) -> bytes:
    """
    Return ``payload`` behind an exported-PDU tag list naming ``dissector``.

    ``tcp_ports`` (source, destination) adds the port tags Modbus TCP needs to tell a query
    (to port 502) from a response.
    """
    name = _pad4(dissector.encode() + b'\0')
    tags = struct.pack('>HH', EXP_PDU_TAG_DISSECTOR_NAME, len(name)) + name
    if tcp_ports is not None:
        source, destination = tcp_ports
        tags += struct.pack('>HHI', EXP_PDU_TAG_PORT_TYPE, 4, PORT_TYPE_TCP)
        tags += struct.pack('>HHI', EXP_PDU_TAG_SRC_PORT, 4, source)
        tags += struct.pack('>HHI', EXP_PDU_TAG_DST_PORT, 4, destination)
    return tags + struct.pack('>HH', EXP_PDU_TAG_END, 0) + payload


def enhanced_packet(interface_id: int, timestamp_ns: int, packet: bytes,
                    inbound: bool, comment: str = '') -> bytes:
    """
    Return an Enhanced Packet Block.

    ``timestamp_ns``: nanoseconds since the epoch (the interface's ``if_tsresol`` is 9);
    ``inbound``: received by the bridge (else sent); ``comment``: shown as ``frame.comment``.
    """
    flags = INBOUND if inbound else OUTBOUND
    options = [(EPB_FLAGS, struct.pack('<I', flags))]
    if comment:
        options.append((OPT_COMMENT, comment.encode()))
    header = struct.pack('<IIIII', interface_id, timestamp_ns >> 32, timestamp_ns & 0xFFFFFFFF,
                         len(packet), len(packet))
    return _block(ENHANCED_PACKET, header + _pad4(packet) + _options(options))
