"""
Replies written at their time by the serving loop, which never sleeps for them.

A simulator's reply that is due later (a ``slow`` or ``late`` fault, a wire-paced reply) is
scheduled here instead of being waited for: the serving loop keeps answering the other
requests and writes each reply when it is due (:meth:`ScheduledWrites.flush_due`), waiting
in its select at most until the next one is (:meth:`ScheduledWrites.timeout_s`). A reply of
a ``late_batched`` fault is held per stream until the next request on that stream arrives
(:meth:`ScheduledWrites.release_held`). Writes due at the same time keep their order; a
write to a stream that was closed before it was due is skipped silently.

Used by one thread, the serving loop's, so it has no lock. Standard library only.
"""

import heapq
from typing import Callable, Dict, List, Protocol, Tuple


class Stream(Protocol):
    """Where a reply goes: a pty master or a TCP client of the simulator."""

    closed: bool

    def write(self, data: bytes) -> None:
        """Send ``data``; a stream that has gone is ignored."""


class ScheduledWrites:
    """A timer queue of writes: a heap of (due time, sequence, stream, bytes)."""

    def __init__(self, clock: Callable[[], float]):
        self.clock = clock
        self._heap: List[Tuple[float, int, Stream, bytes]] = []
        self._sequence = 0
        self._held: Dict[Stream, List[bytes]] = {}

    def __len__(self) -> int:
        """Return the number of writes scheduled and not yet written."""
        return len(self._heap)

    def write_at(self, due_s: float, stream: Stream, data: bytes) -> None:
        """Write ``data`` to ``stream`` at ``due_s`` (now, after any write due before it)."""
        heapq.heappush(self._heap, (due_s, self._sequence, stream, data))
        self._sequence += 1
        self.flush_due(self.clock())

    def flush_due(self, now_s: float) -> None:
        """Write every reply due by ``now_s``, the earliest first (in order at a tie)."""
        while self._heap and self._heap[0][0] <= now_s:
            _, _, stream, data = heapq.heappop(self._heap)
            if not stream.closed:
                stream.write(data)

    def timeout_s(self, now_s: float, longest_s: float) -> float:
        """Return how long the loop may wait in its select: ``longest_s`` at most."""
        if not self._heap:
            return longest_s
        return max(0.0, min(longest_s, self._heap[0][0] - now_s))

    def hold(self, stream: Stream, data: bytes) -> None:
        """Hold ``data`` until the next request on ``stream`` (:meth:`release_held`)."""
        self._held.setdefault(stream, []).append(data)

    def release_held(self, stream: Stream) -> None:
        """Write the replies held for ``stream`` now, in order: its next request came."""
        for data in self._held.pop(stream, []):
            self.write_at(self.clock(), stream, data)

    def forget(self, stream: Stream) -> None:
        """Drop what is held for ``stream`` (it closed); its scheduled writes are skipped."""
        self._held.pop(stream, None)

    def clear(self) -> None:
        """Drop every scheduled and held write (the server stops)."""
        self._heap.clear()
        self._held.clear()
