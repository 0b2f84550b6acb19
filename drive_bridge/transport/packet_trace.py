"""
The wire trace of Modbus TCP: the ADUs pymodbus sends and receives, by transaction.

pymodbus owns that socket, so the bytes are taken where it hands them over: its
``trace_packet`` hook (pymodbus 3.7 and later: called with each packet sent or received) or,
on pymodbus 3.6, the client's ``send``/``recv`` (which its framer calls), wrapped. Received
bytes are cut into ADUs by the MBAP header's length. The records of a transaction are
written when it ends, with its outcome: the request's and that of each reply with the
request's transaction id; a reply with another id is a late one (pymodbus drops it).
"""

from dataclasses import replace
import time
from typing import List, Optional

from drive_bridge.transport.wire_trace import TraceRecord, WireTrace

MBAP_BYTES = 6  # transaction id, protocol id, length: the bytes before the length counts


class PacketTracer:
    """Collect one Modbus TCP transaction's ADUs and write them with its outcome."""

    def __init__(self, trace: WireTrace):
        self.trace = trace
        self._records: List[TraceRecord] = []
        self._received = b''
        self._first_ns = 0  # when the first byte of the ADU being received came

    def packet(self, sending: bool, data: bytes) -> bytes:
        """Note a packet pymodbus sends or received; return it unchanged (its hook's rule)."""
        if not self.trace.enabled:
            return data
        try:
            now_ns = time.time_ns()
            if sending:
                self._records.append(TraceRecord(False, bytes(data), now_ns, now_ns))
            elif data:
                self._receive(bytes(data), now_ns)
        except Exception as error:  # noqa: B902 - whatever it is, pymodbus goes on untraced
            self._stop(error)
        return data

    def wrap(self, client) -> None:
        """Trace a pymodbus 3.6 client through its ``send`` and ``recv``."""
        send, recv = client.send, client.recv

        def traced_send(request):
            self.packet(True, request)
            return send(request)

        def traced_recv(size):
            return self.packet(False, recv(size))

        client.send, client.recv = traced_send, traced_recv

    def end(self, unit: int, error: Optional[BaseException]) -> None:
        """Write the transaction's ADUs: ``error`` None is ok, else its kind; never raise."""
        if not self.trace.enabled:
            self._records, self._received = [], b''
            return
        try:
            self._end(unit, error)
        except Exception as failure:  # noqa: B902 - the transaction's own error goes on
            self._stop(failure)

    def _stop(self, error: Exception) -> None:
        """Stop the trace with its one line; forget what was collected."""
        self._records, self._received = [], b''
        self.trace.fail(error)

    def _end(self, unit: int, error: Optional[BaseException]) -> None:
        outcome = 'ok' if error is None else getattr(error, 'kind', 'link')
        records, self._records = self._records, []
        if self._received:  # part of an ADU: the reply was cut short
            records.append(TraceRecord(True, self._received, self._first_ns, time.time_ns(),
                                       'truncated', unit))
            self._received = b''
        request_id = next((record.data[:2] for record in records if not record.inbound), b'')
        self.trace.write([_settled(record, unit, outcome, request_id) for record in records])

    def _receive(self, data: bytes, now_ns: int) -> None:
        """Add received bytes; note each ADU they complete."""
        if not self._received:
            self._first_ns = now_ns
        self._received += data
        while len(self._received) >= MBAP_BYTES:
            length = MBAP_BYTES + int.from_bytes(self._received[4:6], 'big')
            if len(self._received) < length:
                break
            adu, self._received = self._received[:length], self._received[length:]
            self._records.append(TraceRecord(True, adu, self._first_ns, now_ns))
            self._first_ns = now_ns


def _settled(record: TraceRecord, unit: int, outcome: str, request_id: bytes) -> TraceRecord:
    """Return ``record`` with its outcome: a reply of another transaction id is late."""
    if record.outcome:
        return record
    if record.inbound and record.data[:2] != request_id:
        return replace(record, outcome='late', unit=record.data[MBAP_BYTES])
    return replace(record, outcome=outcome, unit=unit)
