"""
``drive-bridge trace-text FILE.pcapng``: a wire trace as text, one line a frame, to paste.

Reads the pcapng the bridge and the simulator write (:mod:`drive_bridge.protocol.pcapng`:
Section Header, Interface Description, Enhanced Packet blocks with an exported-PDU tag list
before the frame, the direction in ``epb_flags``, outcome, duration and unit in the
comment) and prints each frame as the text form does
(:func:`drive_bridge.transport.wire_trace.text_line`). No tshark needed; blocks of other
types are skipped, a file that is no such pcapng gets one line saying so.
"""

import argparse
import math
import struct
from typing import Dict, Iterator, List, Optional, Tuple

from drive_bridge.errors import ConfigError
from drive_bridge.protocol import pcapng
from drive_bridge.transport.wire_trace import text_line, TraceRecord

MAX_DURATION_MS = 86_400_000.0  # a comment's end time beyond a day is no frame's

Block = Tuple[int, bytes]  # (type, body)


def blocks(data: bytes) -> Iterator[Block]:
    """Yield the blocks of a little-endian pcapng file; raise ValueError where it is broken."""
    position = 0
    while position < len(data):
        if len(data) - position < 12:
            raise ValueError(f'a block cut short at byte {position}')
        block_type, length = struct.unpack_from('<II', data, position)
        if block_type == pcapng.SECTION_HEADER and \
                data[position + 8:position + 12] != struct.pack('<I', pcapng.BYTE_ORDER_MAGIC):
            raise ValueError('a big-endian section: not a drive_bridge trace')
        if length < 12 or length % 4 or position + length > len(data):
            raise ValueError(f'a block of length {length} at byte {position}')
        yield block_type, data[position + 8:position + length - 4]
        position += length


def options(data: bytes) -> Dict[int, bytes]:
    """Return the options of a block's option list (the first of each code)."""
    found: Dict[int, bytes] = {}
    position = 0
    while position + 4 <= len(data):
        code, length = struct.unpack_from('<HH', data, position)
        if code == pcapng.OPT_END:
            break
        found.setdefault(code, data[position + 4:position + 4 + length])
        position += 4 + length + (-length % 4)
    return found


def pdu_payload(packet: bytes) -> bytes:
    """Return the frame behind an exported-PDU tag list."""
    position = 0
    while position + 4 <= len(packet):
        tag, length = struct.unpack_from('>HH', packet, position)
        position += 4
        if tag == pcapng.EXP_PDU_TAG_END:
            return packet[position:]
        position += length
    raise ValueError('a packet without the end of its exported-PDU tags')


def parse_comment(text: str) -> Tuple[str, float, Optional[int]]:
    """Return (outcome, duration in ms, unit) of a record's comment."""
    fields = dict(word.split('=', 1) for word in text.split() if '=' in word)
    unit = fields.get('unit')
    duration_ms = float(fields.get('end', '+0ms').lstrip('+').rstrip('ms') or '0')
    if not math.isfinite(duration_ms) or abs(duration_ms) > MAX_DURATION_MS:
        raise ValueError(f'a frame lasts {duration_ms:g} ms')
    return fields.get('outcome', ''), duration_ms, int(unit) if unit else None


def records(data: bytes) -> Iterator[Tuple[str, TraceRecord]]:
    """Yield (interface name, record) for each packet of a trace."""
    interfaces: List[str] = []
    for block_type, body in blocks(data):
        if block_type == pcapng.SECTION_HEADER:
            interfaces = []
        elif block_type == pcapng.INTERFACE_DESCRIPTION:
            name = options(body[8:]).get(pcapng.IF_NAME, b'?')
            interfaces.append(name.decode(errors='replace'))
        elif block_type == pcapng.ENHANCED_PACKET:
            yield _record(body, interfaces)


def _record(body: bytes, interfaces: List[str]) -> Tuple[str, TraceRecord]:
    interface, high, low, captured, _ = struct.unpack_from('<IIIII', body)
    packet = body[20:20 + captured]
    found = options(body[20 + captured + (-captured % 4):])
    flags = struct.unpack('<I', found.get(pcapng.EPB_FLAGS, bytes(4)))[0]
    outcome, duration_ms, unit = parse_comment(
        found.get(pcapng.OPT_COMMENT, b'').decode(errors='replace'))
    start_ns = (high << 32) | low
    name = interfaces[interface] if interface < len(interfaces) else '?'
    return name, TraceRecord(flags & 3 == pcapng.INBOUND, pdu_payload(packet), start_ns,
                             start_ns + round(duration_ms * 1e6), outcome, unit)


def trace_lines(path: str) -> Iterator[str]:
    """Yield the text lines of the pcapng trace at ``path``; ConfigError if it is none."""
    try:
        with open(path, 'rb') as stream:
            data = stream.read()
    except OSError as error:
        raise ConfigError(f'cannot read {path}: {error.strerror}') from None
    if data[:4] != struct.pack('<I', pcapng.SECTION_HEADER):
        raise ConfigError(f'{path} is no pcapng file (give a .pcapng trace; a .txt trace is '
                          'text already)')
    try:
        for interface, record in records(data):
            yield text_line(record, interface)
    except (ValueError, struct.error) as error:
        raise ConfigError(f'{path}: not a drive_bridge trace ({error})') from None


def command_trace_text(args: argparse.Namespace, out) -> int:
    """Print the trace ``args.file`` as text."""
    for line in trace_lines(args.file):
        print(line, file=out)
    return 0
