"""A fake clock and a scheduler loop for the bus tests (no threads, no real time)."""

import os

from drive_bridge.bus.events import (
    DeviceOffline, DeviceOnline, Notice, ReadingEvent, StateUnknown)

# The bus event types in the words the tests were written in.
EVENT_KINDS = {ReadingEvent: 'reading', DeviceOnline: 'online', DeviceOffline: 'offline',
               StateUnknown: 'error', Notice: 'notice'}


class FakeClock:
    """Monotonic time that moves only when told to (or when the bus sleeps)."""

    def __init__(self):
        self.now = 0.0

    def __call__(self):
        return self.now

    def sleep(self, seconds):
        self.now += seconds


def kind(event):
    """Return a bus event's kind in words: 'reading', 'online', 'offline', 'error', 'notice'."""
    return EVENT_KINDS[type(event)]


def message(event):
    """Return the text a bus event carries ('' for a reading)."""
    return getattr(event, 'message', '')


def run_for(bus, clock, seconds):
    """Run the bus's scheduling steps for ``seconds`` of fake time."""
    end = clock.now + seconds
    while clock.now < end:
        bus.run_step(max_wait_s=end - clock.now)  # the bus sleeps on ``clock``


def drive_cycle(profile, answer, control=None, now_s=0.0):
    """
    Run one poll cycle of ``profile``, begun at ``now_s``, with ``answer(request)`` giving replies.

    ``answer`` may also be a list of replies, in order. Returns (requests sent, reading).
    """
    from drive_bridge.devices.contracts import FixedControl
    replies = list(answer) if isinstance(answer, (list, tuple)) else None
    cycle = profile.poll(control or FixedControl(), now_s)
    requests = []
    result = None
    try:
        step = next(cycle)
        while True:
            requests.append(step.request)
            result = replies.pop(0) if replies is not None else answer(step.request)
            step = cycle.send(result)
    except StopIteration as done:
        return requests, done.value


def poll_requests(profile, control=None, now_s=0.0):
    """Return the first request of a poll cycle of ``profile`` (without running it)."""
    from drive_bridge.devices.contracts import FixedControl
    return next(profile.poll(control or FixedControl(), now_s)).request


_READABLE = os.pipe()
os.write(_READABLE[1], b'x')  # never read: select always finds it readable


def always_readable_fd() -> int:
    """Return a file descriptor that select always reports readable (for fake ports)."""
    return _READABLE[0]


class ScriptedPort:
    """
    A serial port whose wire holds ``reply`` bytes, all there at once (for transports).

    They count as waiting only once a request was written (``early``: before it too, as bytes
    that came after the last transaction ended).
    """

    def __init__(self, reply: bytes, early: bool = False):
        self.reply = reply
        self.timeout = 0.0
        self.written = early

    def reset_input_buffer(self):
        pass

    def write(self, data):
        self.written = True
        return len(data)

    def read(self, count):
        chunk, self.reply = self.reply[:count], self.reply[count:]
        return chunk

    @property
    def in_waiting(self):
        return len(self.reply) if self.written else 0

    def fileno(self):
        return always_readable_fd()

    def close(self):
        pass
