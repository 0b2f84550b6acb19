"""
A Modbus slave bus for the simulators: RTU on a pty, Modbus TCP, or RTU over TCP.

Hand-written rather than pymodbus's server so that it behaves like a real RS-485 line:
addresses it does not serve stay silent (pymodbus answers them with exception 4), vendor
exception codes and timing are exact, and faults can be injected. Standard library only.

With ``wire_baud`` set, each reply is held back until the request and the reply would
have crossed a real wire at that baud rate, 3.5-character gap included, so a pty (which
moves bytes instantly) behaves like a paced line for benchmarks.
"""

from dataclasses import dataclass, field
import os
import selectors
import socket
import struct
import threading
import time
from typing import Callable, Dict, List, Optional, Protocol

from drive_bridge.protocol import rtu
from drive_bridge.protocol.rtu import RtuFrame
from drive_bridge.sim.faults import (
    exception_reply, FaultInjector, mangle_rtu_reply, MBAP_FAULTS, MODBUS_FAULTS)
from drive_bridge.sim.pty_link import PtyLink

GATEWAY_TARGET_FAILED = 0x0B  # Modbus exception: gateway target device failed to respond
STALE_PARTIAL_FRAME_S = 0.05  # a partial frame older than this is dropped (pty has no gaps)


class SimDevice(Protocol):
    """One simulated slave: answers a request frame, or None to stay silent."""

    def handle(self, frame: RtuFrame, now_s: float) -> Optional[RtuFrame]:
        """Answer ``frame`` (addressed to this device) at time ``now_s``."""


@dataclass
class LinkStats:
    """What the server saw on the line (for tests and the console)."""

    requests: int = 0
    replies: int = 0
    crc_errors: int = 0
    dropped: int = 0
    unserved: int = 0
    frames: List[bytes] = field(default_factory=list)


@dataclass
class WireTiming:
    """Wire pacing: replies are held back to the time a real line would deliver them."""

    baudrate: int
    parity: str = 'E'
    stopbits: int = 1

    @property
    def char_s(self) -> float:
        """Return the time of one character on the wire."""
        return rtu.character_time_s(self.baudrate, self.parity, self.stopbits)

    def reply_due(self, request_start_s: float, request_len: int, reply_len: int) -> float:
        """Return when the last byte of the reply would arrive at the master."""
        gap = rtu.frame_gap_s(self.baudrate, self.parity, self.stopbits)
        return request_start_s + (request_len + reply_len) * self.char_s + gap


class _Connection:
    """One byte stream (pty master or TCP client) and its receive buffer."""

    def __init__(self, fd_or_socket, framing: str):
        self.io = fd_or_socket
        self.framing = framing  # 'rtu' or 'mbap'
        self.buffer = b''
        self.first_byte_s = 0.0
        self.last_byte_s = 0.0

    def fileno(self) -> int:
        return self.io if isinstance(self.io, int) else self.io.fileno()

    def read(self) -> bytes:
        if isinstance(self.io, int):
            try:
                return os.read(self.io, 4096)
            except OSError:
                return b''
        try:
            return self.io.recv(4096)
        except OSError:
            return b''

    def write(self, data: bytes) -> None:
        try:
            if isinstance(self.io, int):
                os.write(self.io, data)
            else:
                self.io.sendall(data)
        except OSError:
            pass


class ModbusSimServer:
    """Serve several simulated devices on one simulated bus, on its own thread."""

    def __init__(self, devices: Dict[int, SimDevice], wire: Optional[WireTiming] = None,
                 clock: Callable[[], float] = time.monotonic):
        self.devices = devices
        self.wire = wire
        self.clock = clock
        self.lock = threading.RLock()
        self.stats = LinkStats()
        self.silent_units: set = set()
        self.record_frames = False
        self.faults = FaultInjector(MODBUS_FAULTS)
        # Optional fault hook: (unit, reply bytes) -> bytes to send instead, or None for silence.
        self.reply_hook: Optional[Callable[[int, bytes], Optional[bytes]]] = None
        self.pty_path = ''
        self.tcp_port = 0
        self._selector = selectors.DefaultSelector()
        self._listeners: Dict[int, tuple] = {}
        self._ptys: List[PtyLink] = []
        self._wake_r, self._wake_w = os.pipe()
        self._selector.register(self._wake_r, selectors.EVENT_READ, None)
        self._thread: Optional[threading.Thread] = None
        self._running = False
        self._loop_actions: List[tuple] = []
        self._unplugged_links: List[str] = []

    # -- endpoints ----------------------------------------------------------------------
    def open_pty(self, link_path: str = '') -> str:
        """Open a pty pair, serve RTU on its master; return the slave's path for clients."""
        pty = PtyLink(link_path)
        self._ptys.append(pty)
        self.pty_path = pty.path
        self._selector.register(pty.master, selectors.EVENT_READ,
                                _Connection(pty.master, 'rtu'))
        return self.pty_path

    def open_tcp(self, host: str = '127.0.0.1', port: int = 0, framing: str = 'mbap') -> int:
        """Listen for TCP clients; ``framing`` 'mbap' (Modbus TCP) or 'rtu' (RTU over TCP)."""
        if framing not in ('mbap', 'rtu'):
            raise ValueError(f'framing must be mbap or rtu, not {framing!r}')
        listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        listener.bind((host, port))
        listener.listen(8)
        listener.setblocking(False)
        self._selector.register(listener, selectors.EVENT_READ, ('listen', framing))
        self.tcp_port = listener.getsockname()[1]
        self._listeners[listener.fileno()] = (listener, framing)
        return self.tcp_port

    # -- faults of the line itself ------------------------------------------------------
    def unplug(self) -> None:
        """Close every pty, as a USB adapter pulled out: the port and its symlink vanish."""
        self._in_loop(self._close_ptys)

    def replug(self) -> str:
        """Open a new pty at the same symlink after :meth:`unplug`; return the new path."""
        links = self._unplugged_links
        self._unplugged_links = []
        for link in links or ['']:
            self._in_loop(lambda link=link: self.open_pty(link))
        return self.pty_path

    def close_tcp(self) -> None:
        """Close the TCP listeners and every client connection, as a gateway restarting."""
        self._in_loop(self._close_sockets)

    def power_off(self, unit: int) -> None:
        """Switch a device off: it stays silent until :meth:`power_on`."""
        with self.lock:
            self.silent_units.add(unit)

    def power_on(self, unit: int, device: SimDevice) -> None:
        """Switch a device back on as ``device`` (a fresh one: volatile settings lost)."""
        with self.lock:
            self.devices[unit] = device
            self.silent_units.discard(unit)

    def _in_loop(self, action: Callable[[], None]) -> None:
        """Run ``action`` on the serving thread (the selector is not shared) and wait."""
        if self._thread is None or not self._thread.is_alive():
            action()
            return
        done = threading.Event()
        self._loop_actions.append((action, done))
        os.write(self._wake_w, b'x')
        done.wait(5.0)

    def _close_ptys(self) -> None:
        for pty in self._ptys:
            self._forget(pty.master)
            self._unplugged_links.append(pty.link_path)
            pty.close()
        self._ptys = []

    def _close_sockets(self) -> None:
        for key in list(self._selector.get_map().values()):
            if isinstance(key.fileobj, socket.socket):
                self._close_key(key)
        self._listeners.clear()

    def _forget(self, fileobj) -> bool:
        """Stop watching ``fileobj``; return False if it was not watched."""
        try:
            self._selector.unregister(fileobj)
        except (KeyError, ValueError):
            return False
        return True

    # -- thread -------------------------------------------------------------------------
    def start(self) -> 'ModbusSimServer':
        """Serve on a background thread."""
        self._running = True
        self._thread = threading.Thread(target=self._serve, name='modbus-sim', daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop serving and close every endpoint."""
        self._running = False
        os.write(self._wake_w, b'x')
        if self._thread:
            self._thread.join(timeout=5)
        for key in list(self._selector.get_map().values()):
            self._close_key(key)
        for pty in self._ptys:
            pty.close()
        os.close(self._wake_w)

    def _close_key(self, key) -> None:
        if not self._forget(key.fileobj):
            return
        if isinstance(key.fileobj, socket.socket):
            key.fileobj.close()
        elif key.fileobj == self._wake_r:
            os.close(self._wake_r)

    def _serve(self) -> None:
        while self._running:
            while self._loop_actions:
                action, done = self._loop_actions.pop(0)
                action()
                done.set()
            events = self._selector.select(timeout=0.005)
            now = self.clock()
            for key, _ in events:
                self._on_readable(key, now)
            self._flush_stale(now)

    def _on_readable(self, key, now: float) -> None:
        if key.data is None:
            os.read(self._wake_r, 64)
            return
        if isinstance(key.data, tuple):
            client, _ = key.fileobj.accept()
            client.setblocking(True)
            client.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self._selector.register(client, selectors.EVENT_READ,
                                    _Connection(client, key.data[1]))
            return
        connection: _Connection = key.data
        data = connection.read()
        if not data:
            if isinstance(connection.io, socket.socket):
                self._close_key(key)
            return
        if not connection.buffer:
            connection.first_byte_s = now
        connection.buffer += data
        connection.last_byte_s = now
        self._process(connection, gap_elapsed=False)

    def _flush_stale(self, now: float) -> None:
        for key in list(self._selector.get_map().values()):
            connection = key.data
            if isinstance(connection, _Connection) and connection.buffer and \
                    now - connection.last_byte_s > STALE_PARTIAL_FRAME_S:
                self._process(connection, gap_elapsed=True)

    # -- framing ------------------------------------------------------------------------
    def _process(self, connection: _Connection, gap_elapsed: bool) -> None:
        if connection.framing == 'mbap':
            self._process_mbap(connection)
            return
        while connection.buffer:
            result = rtu.decode_request(connection.buffer, gap_elapsed)
            if result.consumed == 0:
                return
            raw = connection.buffer[:result.consumed]
            connection.buffer = connection.buffer[result.consumed:]
            if result.frame is None:
                with self.lock:
                    self.stats.dropped += 1
                    if result.error == 'CRC error':
                        self.stats.crc_errors += 1
                continue
            fault = self._draw_fault(result.frame, MODBUS_FAULTS)
            reply = self._answer(result.frame, raw, fault)
            if reply is None:
                continue
            data = reply.encode()
            hook = self.reply_hook
            if hook is not None:
                data = hook(reply.unit, data)
            if fault is not None and data:
                data = mangle_rtu_reply(fault, data, self.faults)
            if data:
                self._send_rtu(connection, raw, data, fault == 'slow')

    def _draw_fault(self, frame: RtuFrame, usable: tuple) -> Optional[str]:
        """Return the fault to inject into the reply to ``frame``, if the unit is served."""
        if frame.unit not in self.devices or frame.unit in self.silent_units:
            return None
        return self.faults.draw(frame.unit, usable)

    def _send_rtu(self, connection: _Connection, request: bytes, reply: bytes,
                  slow: bool = False) -> None:
        delay = self.faults.plan.slow_s if slow else 0.0
        if self.wire is not None:
            due = self.wire.reply_due(connection.first_byte_s, len(request), len(reply))
            delay += due - self.clock()
        if delay > 0:
            time.sleep(delay)
        connection.write(reply)

    def _process_mbap(self, connection: _Connection) -> None:
        while len(connection.buffer) >= 7:
            transaction, protocol, length = struct.unpack('>HHH', connection.buffer[:6])
            if protocol != 0 or not 2 <= length <= 254:
                connection.buffer = b''
                with self.lock:
                    self.stats.dropped += 1
                return
            if len(connection.buffer) < 6 + length:
                return
            unit = connection.buffer[6]
            pdu = connection.buffer[7:6 + length]
            connection.buffer = connection.buffer[6 + length:]
            frame = RtuFrame(unit, pdu[0], bytes(pdu[1:]))
            fault = self._draw_fault(frame, MBAP_FAULTS)
            reply = self._answer(frame, frame.encode(), fault)
            if fault == 'no_reply':  # the target executed, its reply was lost: 0Bh
                reply = None
            if fault == 'slow':
                time.sleep(self.faults.plan.slow_s)
            if reply is None:
                reply = rtu.exception_response(unit, frame.function, GATEWAY_TARGET_FAILED)
            body = bytes([reply.unit, reply.function]) + reply.data
            connection.write(struct.pack('>HHH', transaction, 0, len(body)) + body)

    def _answer(self, frame: RtuFrame, raw: bytes,
                fault: Optional[str] = None) -> Optional[RtuFrame]:
        with self.lock:
            self.stats.requests += 1
            if self.record_frames:
                self.stats.frames.append(raw)
            device = self.devices.get(frame.unit)
            if device is None or frame.unit in self.silent_units:
                self.stats.unserved += 1
                return None
            if fault == 'exception':  # busy: the request is not executed
                return exception_reply(frame)
            reply = device.handle(frame, self.clock())
            if reply is not None:
                self.stats.replies += 1
            return reply
