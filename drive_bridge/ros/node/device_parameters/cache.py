"""
The values of one device's parameters as last read, with when (any thread; no rclpy).

The bus thread stores what a read returned (the background refresh, a get, a set's read
back); the executor's services take values from here. A value is kept with the monotonic
time it was read, so that its age can be said. When the device goes offline every value is
forgotten: what it holds may have changed meanwhile (a keypad, a power cycle), and nothing
stale is served as current.
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

    def store(self, number: int, value: Any) -> Optional[Any]:
        """Keep ``value`` as read now; return the value it replaces (None: none)."""
        with self._lock:
            before = self._values.get(number)
            self._values[number] = (value, self._clock())
            self._errors.pop(number, None)
        return None if before is None else before[0]

    def refused(self, number: int, reason: str) -> None:
        """Keep why the device refused to read ``number`` (its value is no longer held)."""
        with self._lock:
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
        """Forget every value (the device went offline)."""
        with self._lock:
            self._values.clear()
            self._errors.clear()

    def __len__(self) -> int:
        with self._lock:
            return len(self._values)
