"""
A Modbus slave bus for the simulators: RTU on a pty, Modbus TCP, or RTU over TCP.

Hand-written rather than pymodbus's server so that it behaves like a real RS-485 line:
addresses it does not serve stay silent (pymodbus answers them with exception 4), vendor
exception codes and timing are exact, and faults can be injected. Standard library only.

With ``wire_baud`` set, each reply is held back until the request and the reply would
have crossed a real wire at that baud rate, 3.5-character gap included, so a pty (which
moves bytes instantly) behaves like a paced line for benchmarks. That, a ``slow`` fault's
delay and a ``late`` fault's reply after the master's timeout are scheduled writes of the
line (:meth:`LineServer.send`); a ``late_batched`` reply is held until the connection's next
request (:meth:`LineServer.hold`). The serving thread never sleeps for a reply.

The endpoints and the serving thread are a :class:`~drive_bridge.sim.line_server.LineServer`,
which hands each stream's bytes to :meth:`ModbusSimServer.take_bytes`; the server here
frames them, picks the device, injects the faults and counts what the line carried.
"""

from dataclasses import dataclass, field
import struct
import threading
import time
from typing import Callable, Dict, List, Optional, Protocol

from drive_bridge.protocol import rtu
from drive_bridge.protocol.rtu import RtuFrame
from drive_bridge.sim.faults import (
    exception_reply, FaultInjector, mangle_rtu_reply, MBAP_FAULTS, MODBUS_FAULTS)
from drive_bridge.sim.line_server import Connection, LineServer

GATEWAY_TARGET_FAILED = 0x0B  # Modbus exception: gateway target device failed to respond


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
        self.line = LineServer(self, clock)

    # -- the line: endpoints, its own faults, the thread (LineServer's) -----------------
    @property
    def pty_path(self) -> str:
        """Return the path of the pty clients open ('' before :meth:`open_pty`)."""
        return self.line.pty_path

    @property
    def tcp_port(self) -> int:
        """Return the TCP port clients connect to (0 before :meth:`open_tcp`)."""
        return self.line.tcp_port

    @property
    def pty_master(self) -> int:
        """Return the pty's master end: bytes written there reach the client (line noise)."""
        return self.line.pty_master

    def open_pty(self, link_path: str = '') -> str:
        """Open a pty pair, serve RTU on its master; return the slave's path for clients."""
        return self.line.open_pty(link_path)

    def open_tcp(self, host: str = '127.0.0.1', port: int = 0, framing: str = 'mbap') -> int:
        """Listen for TCP clients; ``framing`` 'mbap' (Modbus TCP) or 'rtu' (RTU over TCP)."""
        return self.line.open_tcp(host, port, framing)

    def unplug(self) -> None:
        """Close every pty, as a USB adapter pulled out: the port and its symlink vanish."""
        self.line.unplug()

    def replug(self) -> str:
        """Open a new pty at the same symlink after :meth:`unplug`; return the new path."""
        return self.line.replug()

    def close_tcp(self) -> None:
        """Close the TCP listeners and every client connection, as a gateway restarting."""
        self.line.close_tcp()

    def start(self) -> 'ModbusSimServer':
        """Serve on a background thread."""
        self.line.start()
        return self

    def stop(self) -> None:
        """Stop serving and close every endpoint."""
        self.line.stop()

    # -- the devices --------------------------------------------------------------------
    def power_off(self, unit: int) -> None:
        """Switch a device off: it stays silent until :meth:`power_on`."""
        with self.lock:
            self.silent_units.add(unit)

    def power_on(self, unit: int, device: SimDevice) -> None:
        """Switch a device back on as ``device`` (a fresh one: volatile settings lost)."""
        with self.lock:
            self.devices[unit] = device
            self.silent_units.discard(unit)

    # -- framing ------------------------------------------------------------------------
    def take_bytes(self, connection: Connection, gap_elapsed: bool) -> None:
        """Answer the whole frames in ``connection``'s buffer (the line's StreamHandler)."""
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
            self.line.release_held(connection)  # a request came: late_batched replies go
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
                self._send_rtu(connection, raw, data, fault)

    def _draw_fault(self, frame: RtuFrame, usable: tuple) -> Optional[str]:
        """Return the fault to inject into the reply to ``frame``, if the unit is served."""
        if frame.unit not in self.devices or frame.unit in self.silent_units:
            return None
        return self.faults.draw(frame.unit, usable)

    def _send_rtu(self, connection: Connection, request: bytes, reply: bytes,
                  fault: Optional[str] = None) -> None:
        """Write ``reply`` when it is due: at once, at wire time, or as ``fault`` says."""
        due = self.clock()
        if self.wire is not None:
            due = self.wire.reply_due(connection.first_byte_s, len(request), len(reply))
        self._send(connection, reply, fault, due)

    def _send(self, connection: Connection, reply: bytes, fault: Optional[str],
              normal_due_s: float) -> None:
        """Write, schedule or hold ``reply``: ``fault`` may make it slow, late or held."""
        if fault == 'late_batched':
            self.line.hold(connection, reply)
            return
        due = self.faults.plan.reply_due_s(fault, connection.last_byte_s, normal_due_s)
        self.line.send(connection, reply, due)

    def _process_mbap(self, connection: Connection) -> None:
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
            self.line.release_held(connection)  # a request came: late_batched replies go
            frame = RtuFrame(unit, pdu[0], bytes(pdu[1:]))
            fault = self._draw_fault(frame, MBAP_FAULTS)
            reply = self._answer(frame, frame.encode(), fault)
            if fault == 'no_reply':  # the target executed, its reply was lost: 0Bh
                reply = None
            if reply is None:
                reply = rtu.exception_response(unit, frame.function, GATEWAY_TARGET_FAILED)
            body = bytes([reply.unit, reply.function]) + reply.data
            self._send(connection, struct.pack('>HHH', transaction, 0, len(body)) + body,
                       fault, self.clock())

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
