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


class ScriptedLine:
    """
    A byte line on a :class:`FakeClock` with a device behind it (for the line discipline).

    ``device(request, now)`` is called with every write and returns what the device sends
    back: a list of ``(delay_s, bytes)``, each arriving whole ``delay_s`` after the write (or,
    with ``char_s`` set, byte by byte at that pace from then on). ``arrive(delay_s, data)``
    puts bytes on the line without a request. Reads take what has arrived and move the clock
    to the moment the bytes they wait for arrive, or to the end of their timeout.
    """

    def __init__(self, clock: FakeClock, device=None, char_s: float = 0.0):
        self.clock = clock
        self.device = device or (lambda request, now: [])
        self.char_s = char_s
        self.arrivals = []  # (time, byte) not yet read, in time order
        self.writes = []  # (time, bytes)
        self.is_open = False
        self.waits = []  # the timeout of every read that waited

    def connect(self):
        self.is_open = True

    def close(self):
        self.is_open = False

    def arrive(self, delay_s: float, data: bytes) -> None:
        """Put ``data`` on the line ``delay_s`` from now (paced by ``char_s`` if set)."""
        start = self.clock.now + delay_s
        self.arrivals.extend((start + (i + 1) * self.char_s, byte)
                             for i, byte in enumerate(data))
        self.arrivals.sort(key=lambda arrival: arrival[0])

    def write(self, data: bytes, deadline: float) -> None:
        self.writes.append((self.clock.now, bytes(data)))
        for delay_s, reply in self.device(bytes(data), self.clock.now):
            self.arrive(delay_s, reply)

    def _take(self, count: int) -> bytes:
        taken = [byte for moment, byte in self.arrivals if moment <= self.clock.now][:count]
        self.arrivals = self.arrivals[len(taken):]
        return bytes(taken)

    def read(self, count: int, timeout_s: float, at_least: int = 1) -> bytes:
        wanted = min(at_least, count)
        there = sum(1 for moment, _ in self.arrivals if moment <= self.clock.now)
        if there < wanted and timeout_s > 0:
            self.waits.append(timeout_s)
            end = self.clock.now + timeout_s
            if len(self.arrivals) >= wanted and self.arrivals[wanted - 1][0] <= end:
                self.clock.now = max(self.clock.now, self.arrivals[wanted - 1][0])
            else:
                self.clock.now = end
        return self._take(count)

    def wait_quiet(self, timeout_s: float) -> bytes:
        self.clock.now += max(0.0, timeout_s)
        return self._take(len(self.arrivals))
