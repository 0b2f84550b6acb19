"""A fake clock and a scheduler loop for the bus tests (no threads, no real time)."""


class FakeClock:
    """Monotonic time that moves only when told to (or when the bus sleeps)."""

    def __init__(self):
        self.now = 0.0

    def __call__(self):
        return self.now

    def sleep(self, seconds):
        self.now += seconds


def run_for(bus, clock, seconds):
    """Run the bus's scheduling steps for ``seconds`` of fake time."""
    end = clock.now + seconds
    while clock.now < end:
        wait = bus.run_once()
        if wait > 0:
            clock.now += min(wait, end - clock.now)
