"""
A wire trace written by a thread of its own: the line's thread never waits for the disk.

The line discipline hands each transaction's records to :class:`QueuedTrace`, which queues
them (bounded) for its writer thread, where the :class:`~.wire_trace.WireTrace` encodes,
writes and flushes them. A disk that hangs (a stale network mount, a failing USB stick)
stalls the writer only: the bus goes on polling, sending commands and stops. When the queue
is full the newest records are dropped and counted, with one log line; :meth:`close` waits
for the writer a bounded time. Two traces of one file in one process never write at once:
a new one waits for the one before to finish (a search that opens the port at each setting,
a node configured again).
"""

import atexit
import logging
import os
import queue
import threading
from typing import Dict, Iterable, List

from drive_bridge.transport.wire_trace import TraceRecord, WireTrace

LOG = logging.getLogger(__name__)
QUEUED_BATCHES = 4096  # a transaction's records a batch: minutes of a busy line
CLOSE_WAIT_S = 2.0  # how long close waits for the writer to empty the queue
_CLOSE = object()  # the queue's last item
_LIVE: Dict[str, 'QueuedTrace'] = {}  # path -> the trace writing it in this process
_LIVE_LOCK = threading.Lock()


class QueuedTrace:
    """The trace interface of :class:`~.wire_trace.WireTrace`, written by a thread."""

    def __init__(self, trace: WireTrace, queued_batches: int = QUEUED_BATCHES):
        self.trace = trace
        self.dropped = 0  # batches dropped because the writer fell behind
        self._stopped = False
        self._queue: 'queue.Queue' = queue.Queue(queued_batches)
        path = self._path = os.path.abspath(trace.settings.path)
        with _LIVE_LOCK:
            before, _LIVE[path] = _LIVE.get(path), self
        if before is not None:
            before.close()  # its records first, then ours, in the same file
        self._thread = threading.Thread(target=self._run, name=f'wire trace {path}',
                                        daemon=True)
        self._thread.start()

    @property
    def enabled(self) -> bool:
        """Return whether records are still taken."""
        return not self._stopped and self.trace.enabled

    def write(self, records: Iterable[TraceRecord]) -> None:
        """Queue ``records`` for the writer; drop them (counted) if it has fallen behind."""
        if not self.enabled:
            return
        try:
            self._queue.put_nowait(list(records))
        except queue.Full:
            self.dropped += 1
            if self.dropped == 1:
                LOG.error('wire trace %s: the disk is not keeping up; records are dropped '
                          'until it does (the bus goes on)', self.trace.settings.path)

    def fail(self, error: Exception) -> None:
        """Stop the trace with one line (the writer closes the file)."""
        self._stopped = True
        try:
            self._queue.put_nowait(error)
        except queue.Full:
            LOG.error('wire trace %s stopped: %s', self.trace.settings.path, error)

    def drain(self, wait_s: float = CLOSE_WAIT_S) -> bool:
        """Wait at most ``wait_s`` until what is queued is written; return whether it was."""
        written = threading.Event()
        try:
            self._queue.put(written, timeout=wait_s)
        except queue.Full:
            return False
        return written.wait(wait_s)

    def close(self, wait_s: float = CLOSE_WAIT_S) -> None:
        """Write what is queued and close the file, waiting at most ``wait_s``."""
        self._stopped = True
        try:
            self._queue.put(_CLOSE, timeout=wait_s)
        except queue.Full:
            pass
        self._thread.join(wait_s)
        if self._thread.is_alive():
            LOG.error('wire trace %s: the writer is still busy after %g s (a hung disk?); '
                      'left behind', self.trace.settings.path, wait_s)
        with _LIVE_LOCK:
            if _LIVE.get(self._path) is self:
                del _LIVE[self._path]

    def _run(self) -> None:
        while True:
            item = self._queue.get()
            if item is _CLOSE:
                self.trace.close()
                return
            if isinstance(item, threading.Event):
                item.set()
            elif isinstance(item, Exception):
                self.trace.fail(item)
            else:
                self.trace.write(item)


def _close_all() -> None:
    """At exit: let each trace write what is queued (bounded)."""
    with _LIVE_LOCK:
        live: List[QueuedTrace] = list(_LIVE.values())
    for trace in live:
        trace.close()


atexit.register(_close_all)
