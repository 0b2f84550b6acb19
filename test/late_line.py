"""
A line whose far end is a scripted device: answers at set times, late ones included.

For the late-reply tests (issue 40) at the transport's level: the device reads each request
(framed by the protocol's own request decoder) and a script says what it sends back and
when: a list of ``(delay_s, bytes)`` after the request came, written from a timer on the
line's thread, so the device keeps reading while a late reply is pending. ``held`` bytes are
written just before the next request is answered (a gateway that holds a reply until the
next request passes). The line is a pty (the transport opens :attr:`ScriptedDeviceLine.path`)
or a TCP listener (:attr:`ScriptedDeviceLine.tcp_port`, for ``rtu_over_tcp``).
"""

import heapq
import itertools
import os
import select
import socket
import threading
import time
from typing import Callable, List, Optional, Tuple

from drive_bridge.protocol import ap_ascii, rtu
from drive_bridge.protocol import fc_telegram
from drive_bridge.sim.pty_link import PtyLink

Script = Callable[[int, object], List[Tuple[float, bytes]]]  # (request index, request)


def rtu_requests(buffer: bytes) -> Tuple[Optional[object], int]:
    result = rtu.decode_request(buffer)
    return result.frame, result.consumed


def fc_requests(buffer: bytes) -> Tuple[Optional[object], int]:
    result = fc_telegram.decode(buffer)
    return result.telegram, result.consumed


def ascii_requests(buffer: bytes) -> Tuple[Optional[object], int]:
    return ap_ascii.decode_fragment(buffer)


class ScriptedDeviceLine:
    """A scripted device on a pty or TCP line; see the module docstring."""

    def __init__(self, decode: Callable[[bytes], Tuple[Optional[object], int]], script: Script,
                 tcp: bool = False):
        self.decode = decode
        self.script = script
        self.requests: List[Tuple[float, object]] = []  # (arrival, request)
        self.held = b''  # written before the next request is answered
        self.written: List[Tuple[float, bytes]] = []  # (when, bytes) the device sent
        self._due: list = []  # (time, sequence, bytes)
        self._sequence = itertools.count()
        self._lock = threading.Lock()
        self._buffer = b''
        self._running = True
        self._pty: Optional[PtyLink] = None
        self._listener: Optional[socket.socket] = None
        self._stream = -1
        self._client: Optional[socket.socket] = None
        if tcp:
            self._listener = socket.socket()
            self._listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            self._listener.bind(('127.0.0.1', 0))
            self._listener.listen(1)
            self.tcp_port = self._listener.getsockname()[1]
        else:
            self._pty = PtyLink()
            self.path = self._pty.path
            self._stream = self._pty.master
        self._thread = threading.Thread(target=self._serve, daemon=True)
        self._thread.start()

    def send_at(self, delay_s: float, data: bytes) -> None:
        """Write ``data`` ``delay_s`` from now, on the line's thread."""
        with self._lock:
            heapq.heappush(self._due, (time.monotonic() + delay_s, next(self._sequence), data))

    def close(self) -> None:
        self._running = False
        self._thread.join(2.0)
        for closer in (self._pty, self._client, self._listener):
            if closer is not None:
                closer.close()

    def _serve(self) -> None:
        while self._running:
            watched = [self._stream] if self._stream >= 0 else []
            if self._listener is not None and self._client is None:
                watched.append(self._listener)
            with self._lock:
                wait_s = min([0.005] + [due - time.monotonic() for due, _, _ in self._due[:1]])
            ready, _, _ = select.select(watched, [], [], max(0.0, wait_s))
            if self._listener in ready:
                self._client, _ = self._listener.accept()
                self._stream = self._client.fileno()
            elif ready:
                self._take(self._read())
            self._write_due()

    def _read(self) -> bytes:
        try:
            return os.read(self._stream, 4096)
        except (BlockingIOError, OSError):
            return b''

    def _write(self, data: bytes) -> None:
        self.written.append((time.monotonic(), data))
        try:
            if self._client is not None:
                self._client.sendall(data)
            else:
                os.write(self._stream, data)
        except OSError:
            pass

    def _write_due(self) -> None:
        while True:
            with self._lock:
                if not self._due or self._due[0][0] > time.monotonic():
                    return
                _, _, data = heapq.heappop(self._due)
            self._write(data)

    def _take(self, data: bytes) -> None:
        self._buffer += data
        while self._buffer:
            request, consumed = self.decode(self._buffer)
            if consumed == 0:
                return
            self._buffer = self._buffer[consumed:]
            if request is None:
                continue
            index = len(self.requests)
            self.requests.append((time.monotonic(), request))
            if self.held:
                held, self.held = self.held, b''
                self._write(held)
            for delay_s, reply in self.script(index, request):
                self.send_at(delay_s, reply)


def registers_of(frame: rtu.RtuFrame) -> bytes:
    """Return a read's reply: register ``address + i`` holds ``1000 + address + i``."""
    address, count = rtu.parse_address_count(frame.data)
    return rtu.registers_response(frame.unit, frame.function,
                                  [1000 + address + i for i in range(count)]).encode()


def answer_of(frame: rtu.RtuFrame) -> bytes:
    """Return a device's answer to ``frame``: the registers read, or a write's echo."""
    if frame.function == rtu.READ_HOLDING_REGISTERS:
        return registers_of(frame)
    return frame.encode()
