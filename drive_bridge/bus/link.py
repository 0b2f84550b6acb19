"""
Link supervision: the serial port or gateway connection, opened and reopened with backoff.

A lost link (port gone, connection refused, a babbling line) takes every device offline at
once; the link is then reopened after a backoff that doubles up to the bus's maximum.
"""

import time
from typing import Callable

from drive_bridge.errors import LinkDown
from drive_bridge.transport.base import Transport


class LinkSupervisor:
    """Open the link, note why it is down, and say when to try again."""

    def __init__(self, transport: Transport, backoff_initial_s: float, backoff_max_s: float,
                 clock: Callable[[], float] = time.monotonic):
        self.transport = transport
        self.backoff_initial_s = backoff_initial_s
        self.backoff_max_s = backoff_max_s
        self.clock = clock
        self.error = ''  # why the link is down ('' while it is up or untried)
        self.retry_at_s = clock()
        self._backoff_s = 0.0

    @property
    def up(self) -> bool:
        """Return whether the link is open."""
        return self.transport.connected

    def wait_s(self, now_s: float) -> float:
        """Return how long until the next attempt to open the link (0: now)."""
        return max(0.0, self.retry_at_s - now_s)

    def try_open(self) -> bool:
        """Open the link; on failure note why and when to try again."""
        try:
            self.transport.connect()
        except LinkDown as error:
            self.lost(str(error))
            return False
        self.error = ''
        self._backoff_s = 0.0
        return True

    def lost(self, reason: str) -> None:
        """Close the link and plan the next attempt with backoff."""
        self.transport.close()
        self._backoff_s = min(max(self._backoff_s * 2, self.backoff_initial_s),
                              self.backoff_max_s)
        self.retry_at_s = self.clock() + self._backoff_s
        self.error = reason
