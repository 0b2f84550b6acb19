"""
A simulated RS-485 line of drives speaking the Danfoss FC protocol, on a pty or TCP.

Several :class:`~drive_bridge.sim.fc_protocol_device.FcProtocolDevice` faces of
:class:`~drive_bridge.sim.fc_profile_model.FcProfileModel` (FC 51, VLT 5000, VLT 6000) share
one line, as a multidrop bus does: a telegram for an address nobody serves, a broadcast, or a
telegram with a bad BCC gets no reply (confirmed: "only a slave that has received an error-free
telegram addressed to that slave can send a response telegram"; broadcasts are executed
without a reply). TCP carries the same raw bytes (a transparent serial server).

It reuses :class:`~drive_bridge.sim.modbus_server.ModbusSimServer` for the endpoints, the
thread, unplug/replug and power cycling, and replaces the framing. A partial telegram
followed by 50 ms of silence is dropped. With ``wire_baud`` set, each reply is held back
until the request, a 2-character pause and the reply would have crossed a real line; that
wait, like a ``slow`` or ``late`` fault's, is a scheduled write of the line: the serving
thread keeps answering other telegrams meanwhile.

Faults (seeded, counted per address and kind in ``faults.injected``, as the Modbus
simulator's; the master's view in the last column):

==============  ============================================================  ==============
kind            what the simulator does                                       master counts
==============  ============================================================  ==============
bcc             sends the reply with its BCC inverted                         crc
no_reply        executes the telegram, sends nothing                          timeout
slow            sends the reply ``slow_s`` late (still inside the timeout)    slow reply
garbage         STX, then an impossible LGE and noise                         bad_frame
truncated       sends the first part of the reply only                        truncated
wrong_address   sends the reply under the next address (valid BCC)            wrong_address
late            executes; sends the reply ``master_timeout_s + late_s``       timeout
                after the telegram arrived, from a timer
late_batched    executes; holds the reply until the next telegram on the      timeout
                same connection, then sends it just before that one's reply
==============  ============================================================  ==============
"""

from dataclasses import replace
import time
from typing import Callable, Dict, Optional, Tuple

from drive_bridge.protocol import fc_telegram
from drive_bridge.protocol.fc_telegram import FcTelegram
from drive_bridge.sim.faults import FaultInjector, LATE_FAULTS
from drive_bridge.sim.fc_profile_model import FcProfileModel, FcProfileSimConfig
from drive_bridge.sim.fc_protocol_device import FcProtocolDevice
from drive_bridge.sim.line_server import Connection
from drive_bridge.sim.modbus_server import ModbusSimServer

FC_PROTOCOL_FAULTS = ('bcc', 'no_reply', 'slow', 'garbage', 'truncated', 'wrong_address',
                      *LATE_FAULTS)
FC_PROTOCOL_MODELS = ('fc51', 'vlt5000', 'vlt6000')
_IMPOSSIBLE_LGES = (0, 1, 2, 3, 4, 5, 7, 8, 9)


def mangle_fc_reply(kind: str, reply: bytes, injector: FaultInjector) -> Optional[bytes]:
    """Return the bytes to send instead of ``reply`` for fault ``kind`` (None: nothing)."""
    if kind == 'no_reply':
        return None
    if kind == 'bcc':
        return reply[:-1] + bytes([reply[-1] ^ 0xFF])
    if kind == 'truncated':
        return reply[:injector.random_int(1, len(reply) - 1)]
    if kind == 'wrong_address':
        telegram = fc_telegram.decode(reply).telegram
        return replace(telegram, adr=next_address_byte(telegram.adr)).encode()
    if kind == 'garbage':
        lge = _IMPOSSIBLE_LGES[injector.random_int(0, len(_IMPOSSIBLE_LGES) - 1)]
        noise = injector.random_bytes(injector.random_int(4, 12))
        return bytes([fc_telegram.STX, lge]) + noise
    return reply  # 'slow' and the late ones: timed by the server


def next_address_byte(adr: int) -> int:
    """Return the ADR byte of the next address in the same format (wrapping around)."""
    decoded = fc_telegram.decode_address(adr)
    top = 31 if decoded.address_format == fc_telegram.ADDRESS_FORMAT_31 else 126
    return fc_telegram.encode_address(decoded.address % top + 1, decoded.address_format)


class FcProtocolSimServer(ModbusSimServer):
    """Serve FC-protocol drives on one simulated line, on its own thread."""

    def __init__(self, devices: Dict[int, FcProtocolDevice], wire_baud: int = 0,
                 wire_parity: str = fc_telegram.DEFAULT_PARITY,
                 clock: Callable[[], float] = time.monotonic):
        super().__init__(devices, wire=None, clock=clock)
        self.faults = FaultInjector(FC_PROTOCOL_FAULTS)
        self.wire_baud = wire_baud
        self.wire_parity = wire_parity
        self.broadcasts = 0

    def open_tcp(self, host: str = '127.0.0.1', port: int = 0,
                 framing: str = 'rtu') -> int:
        """Listen for TCP clients carrying raw FC-protocol bytes; return the port."""
        return super().open_tcp(host, port, 'rtu')

    # -- framing ------------------------------------------------------------------------
    def take_bytes(self, connection: Connection, gap_elapsed: bool) -> None:
        """Answer the whole telegrams in ``connection``'s buffer (the line's StreamHandler)."""
        while connection.buffer:
            result = fc_telegram.decode(connection.buffer)
            if result.telegram is None and not result.error:
                if gap_elapsed:  # a partial telegram, then silence: drop it
                    connection.buffer = b''
                    with self.lock:
                        self.stats.dropped += 1
                return
            raw = connection.buffer[:result.consumed]
            connection.buffer = connection.buffer[result.consumed:]
            if result.telegram is None:
                with self.lock:
                    self.stats.dropped += 1
                    if result.error == fc_telegram.ERROR_BCC:
                        self.stats.crc_errors += 1
                continue
            self.line.release_held(connection)  # a telegram came: late_batched replies go
            self._serve_telegram(connection, result.telegram, raw)

    def _serve_telegram(self, connection: Connection, telegram: FcTelegram, raw: bytes) -> None:
        device, address = self._addressee(telegram, raw)
        if device is None:
            return
        fault = self.faults.draw(address)
        with self.lock:
            reply = device.handle(telegram, self.clock())
            self.stats.replies += 1
        data = reply.encode()
        hook = self.reply_hook
        if hook is not None:
            data = hook(address, data)
        if fault is not None and data:
            data = mangle_fc_reply(fault, data, self.faults)
        if data:
            self._send_telegram(connection, raw, data, fault)

    def _addressee(self, telegram: FcTelegram,
                   raw: bytes) -> Tuple[Optional[FcProtocolDevice], int]:
        """Return the device that answers ``telegram`` and its address; act on broadcasts."""
        target = telegram.address
        with self.lock:
            self.stats.requests += 1
            if self.record_frames:
                self.stats.frames.append(raw)
            if target.broadcast:
                self.broadcasts += 1
                now = self.clock()
                for unit, device in self.devices.items():
                    if unit not in self.silent_units and device.accepts(telegram.adr):
                        device.handle(telegram, now)
                return None, 0
            device = self.devices.get(target.address)
            if device is None or target.address in self.silent_units or \
                    not device.accepts(telegram.adr):
                self.stats.unserved += 1
                return None, target.address
            return device, target.address

    def _send_telegram(self, connection: Connection, request: bytes, reply: bytes,
                       fault: Optional[str]) -> None:
        """Write ``reply`` when it is due: at once, at wire time, or as ``fault`` says."""
        due = self.clock()
        if self.wire_baud:
            characters = len(request) + fc_telegram.GAP_CHARACTERS + len(reply)
            due = connection.first_byte_s + characters * fc_telegram.character_time_s(
                self.wire_baud, self.wire_parity)
        self._send(connection, reply, fault, due)


def make_fc_protocol_server(models: Dict[int, str], settings: Optional[dict] = None,
                            address_formats: Tuple[str, ...] = fc_telegram.ADDRESS_FORMATS,
                            wire_baud: int = 0) -> FcProtocolSimServer:
    """
    Return a simulated FC-protocol line, one drive per address: ``{1: 'fc51', 2: 'vlt5000'}``.

    ``settings`` are keyword settings of :class:`FcProfileSimConfig` for every drive.
    """
    now = time.monotonic()
    devices = {}
    for address, model in models.items():
        if model not in FC_PROTOCOL_MODELS:
            raise ValueError(f'{model!r} does not speak the FC protocol here: allowed '
                             f'{", ".join(FC_PROTOCOL_MODELS)}')
        config = FcProfileSimConfig(model=model, address=address, protocol='fc_protocol',
                                    baudrate=wire_baud or fc_telegram.DEFAULT_BAUDRATE,
                                    **(settings or {}))
        devices[address] = FcProtocolDevice(FcProfileModel(config, now), address_formats)
    return FcProtocolSimServer(devices, wire_baud=wire_baud)
