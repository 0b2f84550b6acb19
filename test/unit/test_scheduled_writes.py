"""The simulators' timer queue of replies: due order, ties in order, closed streams skipped."""

from typing import List

from drive_bridge.sim.scheduled_writes import ScheduledWrites


class FakeClock:
    def __init__(self):
        self.now_s = 100.0

    def __call__(self) -> float:
        return self.now_s


class Recorder:
    def __init__(self, log: List[bytes]):
        self.log = log
        self.closed = False

    def write(self, data: bytes) -> None:
        self.log.append(data)


def test_a_write_due_now_goes_at_once_and_later_ones_when_due_earliest_first():
    clock, log = FakeClock(), []
    writes, stream = ScheduledWrites(clock), Recorder(log)
    writes.write_at(100.3, stream, b'c')
    writes.write_at(100.1, stream, b'b')
    writes.write_at(0.0, stream, b'a')
    assert log == [b'a'] and len(writes) == 2
    assert writes.timeout_s(clock(), 0.005) == 0.005
    assert abs(writes.timeout_s(100.098, 0.005) - 0.002) < 1e-9
    writes.flush_due(100.2)
    assert log == [b'a', b'b']
    writes.flush_due(100.3)
    assert log == [b'a', b'b', b'c'] and writes.timeout_s(100.4, 0.005) == 0.005


def test_writes_due_at_the_same_time_keep_their_order_and_a_past_due_one_goes_first():
    clock, log = FakeClock(), []
    writes, stream = ScheduledWrites(clock), Recorder(log)
    for data in (b'1', b'2', b'3'):
        writes.write_at(100.5, stream, data)
    clock.now_s = 100.6
    assert writes.timeout_s(clock(), 0.005) == 0.0
    writes.write_at(clock(), stream, b'4')  # due now: after the ones that were due before
    assert log == [b'1', b'2', b'3', b'4']


def test_a_stream_closed_before_its_write_is_due_is_skipped():
    clock, log = FakeClock(), []
    writes, gone, open_ = ScheduledWrites(clock), Recorder(log), Recorder(log)
    writes.write_at(100.1, gone, b'lost')
    writes.write_at(100.2, open_, b'kept')
    gone.closed = True
    writes.flush_due(101.0)
    assert log == [b'kept']


def test_held_writes_go_in_order_when_released_and_only_to_their_stream():
    clock, log, other_log = FakeClock(), [], []
    writes, stream, other = ScheduledWrites(clock), Recorder(log), Recorder(other_log)
    writes.write_at(100.1, stream, b'timed')
    writes.hold(stream, b'held 1')
    writes.hold(stream, b'held 2')
    writes.hold(other, b'other')
    writes.release_held(stream)
    assert log == [b'held 1', b'held 2'] and other_log == []
    writes.release_held(stream)
    assert log == [b'held 1', b'held 2']
    writes.forget(other)
    writes.release_held(other)
    assert other_log == []
    clock.now_s = 100.1
    writes.release_held(stream)
    writes.flush_due(clock())
    assert log == [b'held 1', b'held 2', b'timed']
