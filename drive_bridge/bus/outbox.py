"""
The event outbox: events queued as they happen, given to the listener later, in order.

The bus's parts emit events as they happen (any thread, :meth:`EventOutbox.emit`); the bus
thread delivers them (:meth:`EventOutbox.deliver`) while the next request is on the wire,
or before it waits for anything but the inter-frame gap (see :mod:`.master`), so the
listener's work (publishing) never delays the next frame.
"""

from collections import deque
import threading
from typing import Deque, Optional

from drive_bridge.bus.events import BusEvent, ignore, Listener


class EventOutbox:
    """Events not given to the listener yet, oldest first; one thread delivers at a time."""

    def __init__(self, listener: Optional[Listener] = None):
        self.listener: Listener = listener or ignore
        self._events: Deque[BusEvent] = deque()
        self._delivered = 0  # events given to the listener so far
        self._delivering = threading.Lock()

    @property
    def emitted(self) -> int:
        """Return how many events were emitted so far (delivered or waiting)."""
        return self._delivered + len(self._events)

    @property
    def delivered(self) -> int:
        """Return how many events were given to the listener so far."""
        return self._delivered

    def emit(self, event: BusEvent) -> None:
        """Queue ``event`` for the listener (any thread)."""
        self._events.append(event)

    def deliver(self) -> None:
        """Give the listener every event queued so far, oldest first; never raise."""
        with self._delivering:
            while self._events:
                event = self._events.popleft()
                self._delivered += 1
                try:
                    self.listener(event)
                except Exception:  # noqa: B902 - a listener bug must not kill the bus thread
                    pass
