"""
The simulator's side of the line in a wire trace: requests in, replies out.

``drive_bridge_sim --wire-trace FILE`` writes what the simulator reads (the master's
requests: inbound for it) and writes (its replies, after any fault), in the bridge's trace
format (:mod:`drive_bridge.transport.wire_trace`), one record per read or write: a request
that arrives in pieces is several records. The simulator knows no transaction outcomes, so
its records carry none. Safe to call from any thread (a lock around each write).
"""

import threading
import time
from typing import Optional

from drive_bridge.transport.wire_trace import TraceRecord, WireTrace


class WireTap:
    """Write the bytes a simulated line reads and writes to a wire trace."""

    def __init__(self, trace: WireTrace, stream_protocol: Optional[dict] = None):
        self.trace = trace
        # the protocol of a TCP stream's bytes by its framing ('mbap': Modbus TCP); others:
        # the trace's own
        self.stream_protocol = stream_protocol or {'mbap': 'modbus_tcp'}
        self._lock = threading.Lock()

    def frame(self, inbound: bool, data: bytes, framing: str = '') -> None:
        """Write one read (``inbound``) or write of the simulator, stamped now."""
        now_ns = time.time_ns()
        record = TraceRecord(inbound, bytes(data), now_ns, now_ns,
                             protocol=self.stream_protocol.get(framing, ''))
        with self._lock:
            self.trace.write([record])

    def close(self) -> None:
        """Close the trace file."""
        with self._lock:
            self.trace.close()
