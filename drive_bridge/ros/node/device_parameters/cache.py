"""
The values of one device's parameters as last read, with when (any thread; no rclpy).

The bus thread stores what a read returned (the background refresh, a get, a set's read
back); the executor's services take values from here. A value is kept with the monotonic
time it was read, so that its age can be said. When the device goes offline every value is
forgotten: what it holds may have changed meanwhile (a keypad, a power cycle), and nothing
stale is served as current. Each forgetting starts a new *generation*: a read queued before
it (its answer may come after it) is stored only if no forgetting came in between, so a
value read before an outage is never kept after it.
"""

import threading
import time
from typing import Any, Callable, Dict, Optional, Tuple


class ValueCache:
    """Parameter number -> (value, monotonic time read), under a lock."""

    def __init__(self, clock: Callable[[], float] = time.monotonic):
        self._clock = clock
        self._lock = threading.Lock()
        self._values: Dict[int, Tuple[Any, float]] = {}
        self._errors: Dict[int, str] = {}  # why the device refused the last read
        self._generation = 0  # forgettings so far

    @property
    def generation(self) -> int:
        """Return how many times the values were forgotten (taken when a read is queued)."""
        with self._lock:
            return self._generation

    def store(self, number: int, value: Any, generation: Optional[int] = None) -> Optional[Any]:
        """
        Keep ``value`` as read now; return the value it replaces (None: none).

        With ``generation`` (:attr:`generation` when the read was queued), a value read before
        the last forgetting is not kept (None).
        """
        with self._lock:
            if generation is not None and generation != self._generation:
                return None
            before = self._values.get(number)
            self._values[number] = (value, self._clock())
            self._errors.pop(number, None)
        return None if before is None else before[0]

    def refused(self, number: int, reason: str, generation: Optional[int] = None) -> None:
        """Keep why the device refused to read ``number`` (its value is no longer held)."""
        with self._lock:
            if generation is not None and generation != self._generation:
                return
            self._values.pop(number, None)
            self._errors[number] = reason

    def error(self, number: int) -> str:
        """Return why the device refused the last read of ``number`` ('' if it did not)."""
        with self._lock:
            return self._errors.get(number, '')

    def value(self, number: int) -> Optional[Any]:
        """Return the value last read (None: never read, or forgotten)."""
        with self._lock:
            entry = self._values.get(number)
        return None if entry is None else entry[0]

    def age_s(self, number: int) -> Optional[float]:
        """Return how long ago the value was read (None: not held)."""
        with self._lock:
            entry = self._values.get(number)
        return None if entry is None else self._clock() - entry[1]

    def forget(self) -> None:
        """Forget every value (the device went offline, nobody looks any more)."""
        with self._lock:
            self._values.clear()
            self._errors.clear()
            self._generation += 1

    def __len__(self) -> int:
        with self._lock:
            return len(self._values)
