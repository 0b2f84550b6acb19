"""The wire trace writer: formats by extension, text form, rotation, a write error, trace-text."""

import errno
import io
import logging
import os

from drive_bridge.config.model import build_config
from drive_bridge.errors import ConfigError
from drive_bridge.protocol.crc import append_crc
from drive_bridge.tools import trace_text
from drive_bridge.transport import wire_trace
from drive_bridge.transport.wire_trace import (
    comment, rotated_name, trace_format, TraceRecord, TraceSettings, WireTrace)
import pytest
from trace_helpers import needs_tshark, outcomes, tshark_fields

QUERY = append_crc(bytes([17, 3, 0, 1, 0, 2]))
ANSWER = append_crc(bytes([17, 3, 4, 0x12, 0x34, 0x56, 0x78]))
T0_NS = 1_764_000_000_123_456_789


def exchange(offset_ns=0, outcome='ok'):
    """Return a request and its answer 4.62 ms later, as the discipline records them."""
    start = T0_NS + offset_ns
    return [TraceRecord(False, QUERY, start, start + 8_000, outcome, 17),
            TraceRecord(True, ANSWER, start + 4_620_000, start + 4_700_000, outcome, 17)]


def test_the_format_is_the_extension_s_and_others_are_refused_in_one_line():
    assert trace_format('/tmp/line.pcapng') == 'pcapng'
    assert trace_format('line.TXT') == 'text'
    assert trace_format('line.log') == 'text'
    for name in ('line.pcap', 'line', 'line.cap'):
        with pytest.raises(ConfigError, match=r'name the file \*\.pcapng .* or \*\.txt / \*\.log'):
            trace_format(name)


def test_the_bus_parameters_give_the_trace_settings_and_a_bad_name_is_refused():
    devices = {'starter': {'family': 'mcd', 'address': 20}}
    bus = {'devices': ['starter'], 'wire_trace': '/tmp/line.txt', 'wire_trace_max_mb': 2.5,
           'wire_trace_files': 3}
    assert build_config(bus, devices).trace == TraceSettings('/tmp/line.txt', 2.5, 3)
    assert not build_config({'devices': ['starter']}, devices).trace.enabled
    with pytest.raises(ConfigError, match=r"^parameter 'wire_trace': wire trace 'line.pcap': "
                                          r'name the file \*\.pcapng'):
        build_config(dict(bus, wire_trace='line.pcap'), devices)


def test_the_comment_is_outcome_end_and_unit_words():
    assert comment(TraceRecord(True, b'x', 0, 4_620_000, 'ok', 3)) == \
        'outcome=ok end=+4.62ms unit=3'
    assert comment(TraceRecord(False, b'x', 0, 0, 'timeout')) == 'outcome=timeout end=+0.00ms'
    assert comment(TraceRecord(False, b'x', 0, 0)) == 'end=+0.00ms'


def test_the_text_form_is_one_line_a_frame_with_time_line_direction_bytes_and_outcome(
        tmp_path):
    path = tmp_path / 'line.txt'
    trace = WireTrace(TraceSettings(str(path)), 'ttyUSB0', 'modbus_rtu')
    trace.write(exchange())
    trace.write([TraceRecord(True, ANSWER[:-1] + b'\x00', T0_NS + 9_000_000,
                             T0_NS + 9_000_000, 'crc', 17)])
    lines = path.read_text().splitlines()
    assert lines[0] == '# drive_bridge wire trace: ttyUSB0 modbus_rtu'
    stamp = lines[1][:26]
    assert lines[1] == f'{stamp} ttyUSB0 TX  11 03 00 01 00 02 97 5B  ok 0.01ms unit=17'
    assert lines[2].endswith(' ttyUSB0 RX  11 03 04 12 34 56 78 90 C6  ok 0.08ms unit=17')
    assert lines[3].endswith(' RX  11 03 04 12 34 56 78 90 00  crc 0.00ms unit=17')
    assert lines[1][20:26] == '123456'  # microseconds of the first byte


@needs_tshark
def test_a_pcapng_trace_opens_in_tshark_with_modbus_direction_time_and_outcome(tmp_path):
    path = tmp_path / 'line.pcapng'
    trace = WireTrace(TraceSettings(str(path)), 'ttyUSB0', 'modbus_rtu')
    trace.write(exchange())
    trace.write([TraceRecord(False, QUERY, T0_NS + 10**9, T0_NS + 10**9, 'timeout', 17)])
    trace.close()
    rows = tshark_fields(path, 'frame.p2p_dir', 'frame.time_epoch', 'mbrtu.unit_id',
                         'modbus.func_code', 'modbus.regval_uint16', 'frame.interface_name',
                         'frame.comment')
    assert [row[:5] for row in rows] == [
        ['0', '1764000000.123456789', '17', '3', ''],
        ['1', '1764000000.128076789', '17', '3', '4660,22136'],
        ['0', '1764000001.123456789', '17', '3', '']]
    assert {row[5] for row in rows} == {'ttyUSB0'}
    assert outcomes(rows) == ['ok', 'ok', 'timeout']
    assert rows[1][6] == 'outcome=ok end=+0.08ms unit=17'


@needs_tshark
def test_modbus_tcp_records_carry_the_port_tags_that_tell_query_from_response(tmp_path):
    adu = bytes.fromhex('000100000006110300010002')
    reply = bytes.fromhex('00010000000711030412345678')
    for server_side in (False, True):
        path = tmp_path / f'tcp_{server_side}.pcapng'
        trace = WireTrace(TraceSettings(str(path)), '10.0.0.5:502', 'modbus_tcp', server_side)
        trace.write([TraceRecord(server_side, adu, T0_NS, T0_NS, 'ok', 17),
                     TraceRecord(not server_side, reply, T0_NS + 10**6, T0_NS + 10**6, 'ok',
                                 17)])
        trace.close()
        rows = tshark_fields(path, 'mbtcp.trans_id', 'mbtcp.unit_id', 'modbus.regval_uint16')
        assert rows == [['1', '17', ''], ['1', '17', '4660,22136']], server_side


def test_a_full_file_is_rotated_the_oldest_dropped_and_each_file_stays_within_the_bound(
        tmp_path):
    path = str(tmp_path / 'line.pcapng')
    settings = TraceSettings(path, max_mb=0.01, files=3)  # 10 000 bytes a file
    trace = WireTrace(settings, 'ttyUSB0', 'modbus_rtu')
    for index in range(400):  # about 60 kB
        trace.write(exchange(index * 10**7))
    trace.close()
    assert sorted(os.listdir(tmp_path)) == ['line.1.pcapng', 'line.2.pcapng', 'line.pcapng']
    times = []
    for name in (rotated_name(path, 2), rotated_name(path, 1), path):
        assert os.path.getsize(name) <= settings.max_bytes
        lines = list(trace_text.trace_lines(name))  # each file opens alone
        assert lines and all(' ttyUSB0 ' in line for line in lines)
        times += [line[:26] for line in lines]
    assert times == sorted(times)  # the oldest file holds the oldest frames
    assert trace.records == 800


def test_the_file_of_a_run_before_is_shifted_to_1_not_overwritten(tmp_path, monkeypatch):
    path = str(tmp_path / 'line.txt')
    for run in range(3):
        monkeypatch.setattr(wire_trace, '_WRITTEN_IN_THIS_PROCESS', set())  # another process
        trace = WireTrace(TraceSettings(path, files=2), f'run{run}', 'modbus_rtu')
        trace.write(exchange())
        trace.close()
    assert sorted(os.listdir(tmp_path)) == ['line.1.txt', 'line.txt']
    assert 'run1' in open(rotated_name(path, 1)).readline()
    assert 'run2' in open(path).readline()


@needs_tshark
def test_a_trace_opened_again_in_one_process_goes_on_in_its_file(tmp_path):
    # A command's search opens the port (and its trace) at each setting: one file, whole.
    path = str(tmp_path / 'scan.pcapng')
    for index in range(3):
        trace = WireTrace(TraceSettings(path), f'setting{index}', 'modbus_rtu')
        trace.write(exchange(index * 10**9))
        trace.close()
    assert os.listdir(tmp_path) == ['scan.pcapng']
    rows = tshark_fields(path, 'frame.time_epoch', 'mbrtu.unit_id')  # a section each
    assert [row[1] for row in rows] == ['17'] * 6
    times = [float(row[0]) for row in rows]
    assert times == sorted(times) and times[4] - times[0] == pytest.approx(2.0)


@needs_tshark
def test_a_rotated_pcapng_file_opens_alone_in_tshark(tmp_path):
    path = str(tmp_path / 'line.pcapng')
    trace = WireTrace(TraceSettings(path, max_mb=0.01, files=2), 'ttyUSB0', 'modbus_rtu')
    for index in range(100):
        trace.write(exchange(index * 10**7))
    trace.close()
    for name in (rotated_name(path, 1), path):
        rows = tshark_fields(name, 'mbrtu.unit_id')
        assert rows and {row[0] for row in rows} == {'17'}


class FullDisk(io.BytesIO):
    """A file whose writes fail once ``room`` bytes are in it, as on a full disk."""

    def __init__(self, room: int):
        super().__init__()
        self.room = room
        self.attempts = 0

    def write(self, data) -> int:
        self.attempts += 1
        if self.tell() + len(data) > self.room:
            raise OSError(errno.ENOSPC, 'No space left on device')
        return super().write(data)


def test_a_write_error_stops_the_trace_with_one_line_and_nothing_more_is_tried(
        tmp_path, caplog):
    disk = FullDisk(room=300)
    trace = WireTrace(TraceSettings(str(tmp_path / 'line.pcapng')), 'ttyUSB0', 'modbus_rtu',
                      opener=lambda path: disk)
    with caplog.at_level(logging.ERROR, 'drive_bridge.transport.wire_trace'):
        for index in range(20):
            trace.write(exchange(index))  # never raises
    assert not trace.enabled
    assert len(caplog.records) == 1
    assert caplog.records[0].getMessage().startswith(
        f'wire trace {tmp_path / "line.pcapng"} stopped: [Errno 28] No space left on device '
        '(the bus goes on untraced')
    attempts = disk.attempts
    trace.write(exchange())
    assert disk.attempts == attempts


def test_a_file_that_cannot_be_opened_stops_the_trace_with_one_line(tmp_path, caplog):
    trace = WireTrace(TraceSettings(str(tmp_path / 'missing' / 'line.txt')), 'ttyUSB0',
                      'modbus_rtu')
    with caplog.at_level(logging.ERROR, 'drive_bridge.transport.wire_trace'):
        trace.write(exchange())
        trace.write(exchange())
    assert not trace.enabled
    assert [record.getMessage().split(':')[0] for record in caplog.records] == \
        [f'wire trace {tmp_path / "missing" / "line.txt"} stopped']


def test_trace_text_prints_a_pcapng_trace_as_the_text_form_prints_it(tmp_path):
    records = exchange() + [TraceRecord(True, b'\x15\x03\x00', T0_NS + 7_000_000,
                                        T0_NS + 7_500_000, 'quarantined', None)]
    for name in ('line.pcapng', 'line.txt'):
        trace = WireTrace(TraceSettings(str(tmp_path / name)), 'pts/3', 'modbus_rtu')
        trace.write(records)
        trace.close()
    text = (tmp_path / 'line.txt').read_text().splitlines()[1:]
    assert list(trace_text.trace_lines(str(tmp_path / 'line.pcapng'))) == text


def test_trace_text_refuses_what_is_no_trace_in_one_line(tmp_path):
    (tmp_path / 'x.txt').write_text('# drive_bridge wire trace\n')
    with pytest.raises(ConfigError, match='is no pcapng file'):
        list(trace_text.trace_lines(str(tmp_path / 'x.txt')))
    (tmp_path / 'cut.pcapng').write_bytes(
        (tmp_path / 'x.txt').read_bytes()[:0] + bytes.fromhex('0a0d0d0a') + b'\x40\x00')
    with pytest.raises(ConfigError, match='not a drive_bridge trace'):
        list(trace_text.trace_lines(str(tmp_path / 'cut.pcapng')))
    with pytest.raises(ConfigError, match='cannot read'):
        list(trace_text.trace_lines(str(tmp_path / 'none.pcapng')))


@pytest.mark.parametrize('end', [b'+infms', b'+nanms', b'+1e99ms'])
def test_trace_text_refuses_a_frame_of_no_duration_in_one_line(tmp_path, end):
    path = str(tmp_path / 'line.pcapng')
    trace = WireTrace(TraceSettings(path), 'ttyUSB0', 'modbus_rtu')
    trace.write(exchange())
    trace.close()
    with open(path, 'rb') as stream:  # the same length, so the blocks stay whole
        data = stream.read().replace(b'end=+0.01ms', b'end=' + end.ljust(7))
    with open(path, 'wb') as stream:
        stream.write(data)
    with pytest.raises(ConfigError) as error:
        list(trace_text.trace_lines(path))
    assert 'lasts' in str(error.value) and '\n' not in str(error.value)
