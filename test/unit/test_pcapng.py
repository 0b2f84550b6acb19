"""The pcapng blocks of wire traces, read back by Wireshark's tshark (skipped without it)."""

import shutil
import struct
import subprocess

from drive_bridge.protocol import pcapng
from drive_bridge.protocol.crc import append_crc
import pytest

TSHARK = shutil.which('tshark')
needs_tshark = pytest.mark.skipif(
    TSHARK is None, reason='tshark is not installed: apt-get install tshark (.ci/run does)')

# A read of 2 holding registers from address 1 at unit 17, and its answer.
QUERY = append_crc(bytes([17, 3, 0, 1, 0, 2]))
ANSWER = append_crc(bytes([17, 3, 4, 0x12, 0x34, 0x56, 0x78]))
T0_NS = 1_764_000_000_123_456_789


def test_blocks_are_whole_words_with_their_length_at_both_ends():
    for block in (pcapng.section_header(), pcapng.interface_description('/dev/ttyUSB0', 'x'),
                  pcapng.enhanced_packet(0, T0_NS, b'abc', inbound=True, comment='ok')):
        assert len(block) % 4 == 0
        assert struct.unpack('<I', block[4:8]) == struct.unpack('<I', block[-4:])
        assert struct.unpack('<I', block[4:8])[0] == len(block)


def test_exported_pdu_names_the_dissector_padded_to_four_bytes():
    tags = pcapng.exported_pdu('mbrtu', b'\x01')
    assert tags == struct.pack('>HH', 12, 8) + b'mbrtu\0\0\0' + struct.pack('>HH', 0, 0) + b'\x01'


def write_trace(path, packets):
    with open(path, 'wb') as trace:
        trace.write(pcapng.section_header())
        trace.write(pcapng.interface_description('/dev/ttyUSB0'))
        for offset_ns, dissector, payload, inbound, comment, ports in packets:
            trace.write(pcapng.enhanced_packet(
                0, T0_NS + offset_ns, pcapng.exported_pdu(dissector, payload, ports),
                inbound, comment))


def tshark_fields(path, *fields):
    command = [TSHARK, '-r', str(path), '-T', 'fields', '-E', 'separator=|']
    for field in fields:
        command += ['-e', field]
    done = subprocess.run(command, capture_output=True, text=True, timeout=60, check=True)
    assert 'error' not in done.stderr.lower(), done.stderr
    return [line.split('|') for line in done.stdout.splitlines()]


@needs_tshark
def test_tshark_decodes_modbus_rtu_with_direction_time_and_comment(tmp_path):
    path = tmp_path / 'rtu.pcapng'
    write_trace(path, [(0, 'mbrtu', QUERY, False, 'sent', None),
                       (5_000_000, 'mbrtu', ANSWER, True, 'ok, end +4.6 ms', None)])
    rows = tshark_fields(path, 'frame.p2p_dir', 'frame.time_epoch', 'mbrtu.unit_id',
                         'modbus.func_code', 'modbus.regval_uint16', 'frame.comment')
    assert rows[0][:4] == ['0', '1764000000.123456789', '17', '3']
    assert rows[1][0] == '1' and rows[1][1] == '1764000000.128456789'
    assert rows[1][4] == '4660,22136' and rows[1][5] == 'ok, end +4.6 ms'


@needs_tshark
def test_tshark_decodes_modbus_tcp_query_and_response_by_port(tmp_path):
    mbap_query = struct.pack('>HHHB', 7, 0, 6, 1) + bytes([3, 0, 1, 0, 2])
    mbap_answer = struct.pack('>HHHB', 7, 0, 7, 1) + bytes([3, 4, 0x12, 0x34, 0x56, 0x78])
    path = tmp_path / 'tcp.pcapng'
    write_trace(path, [(0, 'mbtcp', mbap_query, False, '', (50123, 502)),
                       (1_000_000, 'mbtcp', mbap_answer, True, '', (502, 50123))])
    rows = tshark_fields(path, 'mbtcp.trans_id', 'modbus.func_code', 'modbus.regval_uint16')
    assert rows == [['7', '3', ''], ['7', '3', '4660,22136']]
