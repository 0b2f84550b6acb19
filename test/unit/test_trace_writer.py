"""The wire trace's writer thread: the line's thread never waits for the disk."""

import logging
import threading
import time

from drive_bridge.transport.trace_writer import QueuedTrace
from drive_bridge.transport.wire_trace import TraceRecord, TraceSettings, WireTrace

T0_NS = 1_764_000_000_000_000_000


def records(index):
    start = T0_NS + index * 10**7
    return [TraceRecord(False, bytes([17, 3, 0, index % 256, 0, 2, 0, 0]), start, start, 'ok',
                        17)]


class HungDisk:
    """An opener whose file blocks every write until ``release`` is set."""

    def __init__(self, path):
        self.release = threading.Event()
        self.path = path

    def __call__(self, path):
        disk = self

        class Stuck:
            def write(self, data):
                disk.release.wait(30.0)
                return len(data)

            def flush(self):
                pass

            def close(self):
                pass
        return Stuck()


def test_records_reach_the_file_in_order_and_close_writes_what_is_queued(tmp_path):
    path = tmp_path / 'line.txt'
    trace = QueuedTrace(WireTrace(TraceSettings(str(path)), 'ttyUSB0', 'modbus_rtu'))
    for index in range(200):
        trace.write(records(index))
    trace.close()
    lines = path.read_text().splitlines()[1:]
    assert [int(line.split()[7], 16) for line in lines] == [index % 256 for index in range(200)]


def test_a_hung_disk_never_holds_the_line_s_thread(tmp_path, caplog):
    disk = HungDisk(str(tmp_path / 'line.txt'))
    trace = QueuedTrace(WireTrace(TraceSettings(disk.path), 'ttyUSB0', 'modbus_rtu',
                                  opener=disk), queued_batches=3)
    try:
        with caplog.at_level(logging.ERROR, 'drive_bridge.transport.trace_writer'):
            started = time.monotonic()
            for index in range(100):  # the writer is stuck in its first write
                trace.write(records(index))
            assert time.monotonic() - started < 1.0  # no write waited for the disk
            assert trace.dropped >= 95
            assert not trace.drain(0.1)  # it says so, after a bounded wait
            started = time.monotonic()
            trace.close(wait_s=0.2)
            assert time.monotonic() - started < 1.0
        messages = [record.getMessage() for record in caplog.records]
        assert len([m for m in messages if 'not keeping up' in m]) == 1
        assert any('still busy' in m for m in messages)
    finally:
        disk.release.set()


def test_a_second_trace_of_one_file_waits_for_the_first(tmp_path):
    path = str(tmp_path / 'line.txt')
    first = QueuedTrace(WireTrace(TraceSettings(path), 'first', 'modbus_rtu'))
    for index in range(50):
        first.write(records(index))
    second = QueuedTrace(WireTrace(TraceSettings(path), 'second', 'modbus_rtu'))
    second.write(records(99))
    second.close()
    names = [line.split()[2] for line in open(path).read().splitlines()
             if not line.startswith('#')]
    assert names == ['first'] * 50 + ['second']
    assert not first.enabled


def test_a_failure_stops_it_with_one_line_from_the_writer(tmp_path, caplog):
    trace = QueuedTrace(WireTrace(TraceSettings(str(tmp_path / 'line.txt')), 'x',
                                  'modbus_rtu'))
    with caplog.at_level(logging.ERROR, 'drive_bridge.transport.wire_trace'):
        trace.fail(ValueError('a record that cannot be encoded'))
        assert not trace.enabled
        trace.write(records(1))  # taken no more
        trace.close()
    assert [r.getMessage().split(':')[0] for r in caplog.records] == \
        [f'wire trace {tmp_path / "line.txt"} stopped']


def test_drain_waits_for_what_is_queued(tmp_path):
    path = tmp_path / 'line.txt'
    trace = QueuedTrace(WireTrace(TraceSettings(str(path)), 'ttyUSB0', 'modbus_rtu'))
    trace.write(records(1))
    assert trace.drain(5.0)
    assert len(path.read_text().splitlines()) == 2
    trace.close()
