"""
Link health: the serial port or gateway connection, opened and reopened with backoff.

A lost link (port gone, connection refused, a babbling line) takes every device offline at
once: :class:`LinkHealth` closes it, plans the next attempt after a backoff that doubles up
to the bus's maximum, and tells its watcher (the poll scheduler, which drops the cycle in
progress and takes every device offline). Once the link opens again the watcher makes every
device due at once.
"""

import time
from typing import Callable

from drive_bridge.bus.seams import LinkWatcher
from drive_bridge.errors import LinkDown
from drive_bridge.transport.base import Transport


class LinkHealth:
    """Open the link, note why it is down, say when to try again, tell the watcher."""

    def __init__(self, transport: Transport, backoff_initial_s: float, backoff_max_s: float,
                 watcher: LinkWatcher, clock: Callable[[], float] = time.monotonic):
        self.transport = transport
        self.backoff_initial_s = backoff_initial_s
        self.backoff_max_s = backoff_max_s
        self.watcher = watcher
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
        """Open the link (every device is due at once); on failure it is lost again."""
        try:
            self.transport.connect()
        except LinkDown as error:
            self.lost(str(error))
            return False
        self.error = ''
        self._backoff_s = 0.0
        self.watcher.link_opened()
        return True

    def lost(self, reason: str) -> None:
        """Close the link, plan the next attempt with backoff, take every device offline."""
        self.transport.close()
        self._backoff_s = min(max(self._backoff_s * 2, self.backoff_initial_s),
                              self.backoff_max_s)
        self.retry_at_s = self.clock() + self._backoff_s
        self.error = reason
        self.watcher.link_lost(reason)
