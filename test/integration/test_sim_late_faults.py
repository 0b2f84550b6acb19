"""
The simulators' late replies, and reply timing that never blocks their serving thread.

``late``: the device executes the request at once and its reply comes ``master_timeout_s +
late_s`` after the request, from a timer, while other requests are answered. ``late_batched``:
the reply is held until the next request on the same connection, and comes just before that
request's own reply. ``slow`` and wire pacing wait on the same timer: a slow reply no longer
holds up the line.

Raw clients only (a pty or a TCP socket, select and bytes): not drive_bridge.transport. A
reply's time is taken when this test reads it, never sooner than it came, so a check that a
reply is not early holds on any machine; the checks that it is not too late are generous,
and the order of replies on the stream is what shows that nothing blocked.
"""

from dataclasses import dataclass, replace
import os
import select
import socket
import struct
import time
from typing import List, Optional

from drive_bridge.protocol import ap_ascii, rtu
from drive_bridge.protocol import fc_telegram
from drive_bridge.protocol.crc import crc_ok
from drive_bridge.protocol.fc_profile import START_WORD
from drive_bridge.protocol.rtu import RtuFrame
from drive_bridge.sim import cli as sim_cli
from drive_bridge.sim.ap_ascii_server import make_ap_ascii_server
from drive_bridge.sim.faults import FaultInjector, FaultPlan, MODBUS_FAULTS, parse_fault_plan
from drive_bridge.sim.fc_protocol_server import make_fc_protocol_server
from drive_bridge.sim.lvsg_gateway import make_lvsg_gateway
from drive_bridge.sim.mcd_device import make_mcd_server
from drive_bridge.sim.mcd_model import STARTING
from drive_bridge.sim.modbus_server import WireTiming
from integration_helpers import wait_until
import pytest

MASTER_TIMEOUT_S = 0.4
LATE_S = 0.05
SLOW_S = 0.5
READ_TIMEOUT_S = 10.0  # generous: the machine may be loaded
QUIET_S = 0.2  # a held reply must not come within this (after the request was executed)
START, STATUS = 1, 2  # MCD registers 40002 (command: 1 = start) and 40003 (status)
MCD_A, MCD_B = 20, 21
FC51, VLT5000 = 1, 2
HALF_SPEED = 0x2000


# -- a raw master -------------------------------------------------------------------------
@dataclass(frozen=True)
class Reply:
    """One whole reply as read: its address, its kind and (Modbus TCP) transaction id."""

    unit: int
    kind: int  # Modbus: the function code; FC protocol: the LGE; AP ASCII: the first byte
    tid: Optional[int]
    data: bytes
    at_s: float  # when this test had read it whole (never before it came)


class RtuCodec:
    """Modbus RTU frames, on a pty or RTU over TCP."""

    def request(self, frame: RtuFrame) -> bytes:
        return frame.encode()

    def length(self, buffer: bytes) -> Optional[int]:
        return rtu.response_length(buffer)

    def reply(self, data: bytes, at_s: float) -> Reply:
        assert crc_ok(data), data.hex(' ')
        return Reply(data[0], data[1], None, data, at_s)


class MbapCodec:
    """Modbus TCP: each request gets the next transaction id, from 1."""

    def __init__(self):
        self.tid = 0

    def request(self, frame: RtuFrame) -> bytes:
        self.tid += 1
        pdu = bytes([frame.unit, frame.function]) + frame.data
        return struct.pack('>HHH', self.tid, 0, len(pdu)) + pdu

    def length(self, buffer: bytes) -> Optional[int]:
        return 6 + struct.unpack('>H', buffer[4:6])[0] if len(buffer) >= 6 else None

    def reply(self, data: bytes, at_s: float) -> Reply:
        tid, protocol, length = struct.unpack('>HHH', data[:6])
        assert protocol == 0 and len(data) == 6 + length, data.hex(' ')
        return Reply(data[6], data[7], tid, data, at_s)


class FcCodec:
    """FC protocol telegrams: STX LGE ADR ... BCC."""

    def request(self, telegram: fc_telegram.FcTelegram) -> bytes:
        return telegram.encode()

    def length(self, buffer: bytes) -> Optional[int]:
        return buffer[1] + 2 if len(buffer) >= 2 else None

    def reply(self, data: bytes, at_s: float) -> Reply:
        result = fc_telegram.decode(data)
        assert result.telegram is not None, (result, data.hex(' '))
        return Reply(result.telegram.address.address, data[1], None, data, at_s)


class AsciiCodec:
    """AP ASCII replies: ACK, NAK, BEL (one byte) or a data fragment (8 bytes)."""

    def request(self, fragment: bytes) -> bytes:
        return fragment

    def length(self, buffer: bytes) -> Optional[int]:
        if not buffer:
            return None
        return ap_ascii.FRAME_BYTES if buffer[0] == ap_ascii.STX else 1

    def reply(self, data: bytes, at_s: float) -> Reply:
        frame = ap_ascii.ReplyFramer.cut(data).frame
        assert frame is not None and frame.valid and len(frame.raw) == len(data), data
        return Reply(0, data[0], None, data, at_s)


class RawMaster:
    """Writes requests and reads whole replies with select, on a pty or a TCP socket."""

    def __init__(self, fd: int, codec, keep=None):
        self.fd = fd
        self.codec = codec
        self.buffer = b''
        self._keep = keep  # the socket object, if any (its fd is ours while it lives)

    @classmethod
    def on_pty(cls, path: str, codec) -> 'RawMaster':
        return cls(os.open(path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK), codec)

    @classmethod
    def on_tcp(cls, port: int, codec) -> 'RawMaster':
        sock = socket.create_connection(('127.0.0.1', port), timeout=READ_TIMEOUT_S)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        sock.setblocking(False)
        return cls(sock.fileno(), codec, sock)

    def send(self, request) -> float:
        """Write a request whole; return the time just before it was written."""
        data = self.codec.request(request)
        started = time.monotonic()
        while data:
            try:
                data = data[os.write(self.fd, data):]
            except BlockingIOError:
                select.select([], [self.fd], [], 0.05)
        return started

    def replies(self, count: int, timeout_s: float = READ_TIMEOUT_S) -> List[Reply]:
        """Read until ``count`` whole replies have come; fail if they do not in time."""
        deadline = time.monotonic() + timeout_s
        replies: List[Reply] = []
        while len(replies) < count:
            length = self.codec.length(self.buffer)
            if length is not None and len(self.buffer) >= length:
                replies.append(self.codec.reply(self.buffer[:length], time.monotonic()))
                self.buffer = self.buffer[length:]
                continue
            remaining_s = deadline - time.monotonic()
            assert remaining_s > 0, f'{len(replies)} of {count} replies, then {self.buffer!r}'
            self._read(remaining_s)
        return replies

    def quiet_for(self, duration_s: float) -> bool:
        """Return whether nothing at all arrives within ``duration_s``."""
        deadline = time.monotonic() + duration_s
        while not self.buffer and time.monotonic() < deadline:
            self._read(deadline - time.monotonic())
        return not self.buffer

    def _read(self, timeout_s: float) -> None:
        ready, _, _ = select.select([self.fd], [], [], max(0.0, timeout_s))
        if ready:
            try:
                self.buffer += os.read(self.fd, 4096)
            except (BlockingIOError, InterruptedError):
                pass

    def close(self) -> None:
        if self._keep is not None:
            self._keep.close()
        else:
            os.close(self.fd)


def time_late_replies(server, **timing) -> None:
    """Give the server's fault plan this test's timing (no random faults)."""
    timing = {'master_timeout_s': MASTER_TIMEOUT_S, 'late_s': LATE_S, 'slow_s': SLOW_S,
              **timing}
    server.faults.set_plan(replace(server.faults.plan, **timing))


def late_by_s() -> float:
    return MASTER_TIMEOUT_S + LATE_S


# -- Modbus: RTU on a pty, RTU over TCP, Modbus TCP ---------------------------------------
MODBUS_ENDPOINTS = ('rtu_pty', 'rtu_tcp', 'mbap')


@pytest.fixture(params=MODBUS_ENDPOINTS)
def modbus(request):
    """Serve an MCD 500 at 20 and an MCD 202 at 21; yield the server and a raw master."""
    server = make_mcd_server({MCD_A: 'mcd500', MCD_B: 'mcd202'}, start_time_s=5.0)
    time_late_replies(server)
    if request.param == 'rtu_pty':
        server.open_pty()
    else:
        server.open_tcp(framing={'rtu_tcp': 'rtu', 'mbap': 'mbap'}[request.param])
    server.start()
    if request.param == 'rtu_pty':
        master = RawMaster.on_pty(server.pty_path, RtuCodec())
    else:
        codec = MbapCodec() if request.param == 'mbap' else RtuCodec()
        master = RawMaster.on_tcp(server.tcp_port, codec)
    yield server, master
    master.close()
    server.stop()


def mcd_state(server, unit: int) -> int:
    with server.lock:
        model = server.devices[unit].model
        model.advance(time.monotonic())
        return model.state


def start_request(unit: int = MCD_A) -> RtuFrame:
    return rtu.write_register_request(unit, START, 1)


def status_request(unit: int) -> RtuFrame:
    return rtu.read_registers_request(unit, STATUS, 1)


def test_a_late_modbus_reply_comes_after_the_timeout_and_the_line_is_served_meanwhile(
        modbus):
    server, master = modbus
    server.faults.inject(MCD_A, 'late')
    sent_s = master.send(start_request())
    master.send(status_request(MCD_B))  # another unit
    master.send(status_request(MCD_A))  # the same unit
    replies = master.replies(2)
    assert mcd_state(server, MCD_A) == STARTING  # the start was executed, not yet answered
    replies += master.replies(1)
    assert [(reply.unit, reply.kind) for reply in replies] == [
        (MCD_B, rtu.READ_HOLDING_REGISTERS), (MCD_A, rtu.READ_HOLDING_REGISTERS),
        (MCD_A, rtu.WRITE_SINGLE_REGISTER)]
    if isinstance(master.codec, MbapCodec):
        assert [reply.tid for reply in replies] == [2, 3, 1]  # the late one keeps its id
    else:
        assert replies[2].data == start_request().encode()  # the whole echo
    late = replies[2].at_s - sent_s
    assert late_by_s() <= late < late_by_s() + READ_TIMEOUT_S / 2, late
    assert server.faults.totals() == {'late': 1}


def test_a_late_batched_modbus_reply_comes_just_before_the_next_reply(modbus):
    server, master = modbus
    server.faults.inject(MCD_A, 'late_batched')
    master.send(start_request())
    assert wait_until(lambda: mcd_state(server, MCD_A) == STARTING)  # executed
    assert master.quiet_for(QUIET_S), master.buffer  # but not answered
    next_sent_s = master.send(status_request(MCD_B))
    replies = master.replies(2)
    assert [(reply.unit, reply.kind) for reply in replies] == [
        (MCD_A, rtu.WRITE_SINGLE_REGISTER), (MCD_B, rtu.READ_HOLDING_REGISTERS)]
    assert replies[0].at_s >= next_sent_s
    if isinstance(master.codec, MbapCodec):
        assert [reply.tid for reply in replies] == [1, 2]
    assert server.faults.totals() == {'late_batched': 1}


def test_late_batched_replies_are_each_released_by_the_next_request(modbus):
    server, master = modbus
    server.faults.inject(MCD_A, 'late_batched', count=2)
    master.send(start_request())
    master.send(status_request(MCD_A))  # releases the start's echo; its own reply is held
    first, = master.replies(1)
    assert (first.unit, first.kind) == (MCD_A, rtu.WRITE_SINGLE_REGISTER)
    assert master.quiet_for(QUIET_S), master.buffer
    master.send(status_request(MCD_B))
    assert [(reply.unit, reply.kind) for reply in master.replies(2)] == [
        (MCD_A, rtu.READ_HOLDING_REGISTERS), (MCD_B, rtu.READ_HOLDING_REGISTERS)]
    assert server.faults.injected[(MCD_A, 'late_batched')] == 2


def test_a_slow_modbus_reply_no_longer_holds_up_the_line(modbus):
    server, master = modbus
    server.faults.inject(MCD_A, 'slow')
    sent_s = master.send(status_request(MCD_A))
    master.send(status_request(MCD_B))
    replies = master.replies(2)
    assert [reply.unit for reply in replies] == [MCD_B, MCD_A]
    assert replies[1].at_s - sent_s >= SLOW_S
    assert server.faults.totals() == {'slow': 1}


def test_a_late_reply_for_a_pty_unplugged_meanwhile_is_dropped():
    server = make_mcd_server({MCD_A: 'mcd500'})
    time_late_replies(server)
    server.open_pty()
    server.start()
    master = RawMaster.on_pty(server.pty_path, RtuCodec())
    try:
        server.faults.inject(MCD_A, 'late')
        master.send(status_request(MCD_A))
        assert wait_until(lambda: len(server.line.writes) == 1)  # the late reply, pending
        master.close()
        server.unplug()
        master = RawMaster.on_pty(server.replug(), RtuCodec())  # may get the same fd number
        assert wait_until(lambda: len(server.line.writes) == 0, timeout_s=READ_TIMEOUT_S)
        master.send(status_request(MCD_A))
        reply, = master.replies(1)
        assert reply.unit == MCD_A and master.quiet_for(QUIET_S), master.buffer
    finally:
        master.close()
        server.stop()


def test_a_late_reply_for_a_tcp_client_that_left_is_dropped():
    server = make_mcd_server({MCD_A: 'mcd500'})
    time_late_replies(server)
    server.open_tcp()
    server.start()
    gone = RawMaster.on_tcp(server.tcp_port, MbapCodec())
    master = RawMaster.on_tcp(server.tcp_port, MbapCodec())
    try:
        server.faults.inject(MCD_A, 'late')
        gone.send(status_request(MCD_A))
        assert wait_until(lambda: len(server.line.writes) == 1)  # the late reply, pending
        gone.close()
        assert wait_until(lambda: len(server.line.writes) == 0, timeout_s=READ_TIMEOUT_S)
        master.send(status_request(MCD_A))  # the line still serves
        assert master.replies(1)[0].tid == 1
    finally:
        master.close()
        server.stop()


def test_a_wire_paced_reply_no_longer_holds_up_the_other_connections():
    # 150 baud 8E1: a request and its reply (8 + 7 characters) take 1.1 s on the wire. A
    # thread that slept for the first reply would read the second request only then, and
    # answer it 1.1 s later still.
    wire = WireTiming(150, 'E', 1)
    wire_s = wire.reply_due(0.0, 8, 7)
    server = make_mcd_server({MCD_A: 'mcd500', MCD_B: 'mcd202'}, wire=wire)
    server.open_pty()
    server.open_tcp(framing='rtu')
    server.start()
    on_tcp = RawMaster.on_tcp(server.tcp_port, RtuCodec())
    on_pty = RawMaster.on_pty(server.pty_path, RtuCodec())
    try:
        tcp_sent_s = on_tcp.send(status_request(MCD_A))
        pty_sent_s = on_pty.send(status_request(MCD_B))
        tcp_reply, = on_tcp.replies(1)
        pty_reply, = on_pty.replies(1)
        assert tcp_reply.at_s - tcp_sent_s >= wire_s and pty_reply.at_s - pty_sent_s >= wire_s
        assert pty_reply.at_s < tcp_reply.at_s + wire_s / 2, 'the line was held up'
    finally:
        on_tcp.close()
        on_pty.close()
        server.stop()


def test_the_lvsg_gateway_executes_a_late_fwd_run_at_once():
    server = make_lvsg_gateway({0: ('mcd202', 100, 'extended')}, start_time_s=5.0)
    time_late_replies(server)
    server.open_pty()
    server.start()
    master = RawMaster.on_pty(server.pty_path, RtuCodec())
    slave_model = server.devices[1].slaves[0].model
    try:
        server.faults.inject(1, 'late')
        sent_s = master.send(rtu.write_register_request(1, 100, 0x0100))  # Fwd Run
        master.send(rtu.read_registers_request(1, 0, 3))  # the input image, answered first
        image, = master.replies(1)
        assert image.kind == rtu.READ_HOLDING_REGISTERS and slave_model.state == STARTING
        reply, = master.replies(1)
        assert reply.kind == rtu.WRITE_SINGLE_REGISTER and reply.at_s - sent_s >= late_by_s()
    finally:
        master.close()
        server.stop()


# -- the FC protocol, on a pty and raw over TCP -------------------------------------------
@pytest.fixture(params=('pty', 'tcp'))
def fc_line(request):
    """Serve an FC 51 at 1 and a VLT 5000 at 2; yield the server and a raw master."""
    server = make_fc_protocol_server({FC51: 'fc51', VLT5000: 'vlt5000'})
    time_late_replies(server)
    if request.param == 'pty':
        server.open_pty()
    else:
        server.open_tcp()
    server.start()
    master = RawMaster.on_pty(server.pty_path, FcCodec()) if request.param == 'pty' else \
        RawMaster.on_tcp(server.tcp_port, FcCodec())
    yield server, master
    master.close()
    server.stop()


def fc_start(address: int) -> fc_telegram.FcTelegram:
    return fc_telegram.process_request(START_WORD, HALF_SPEED).telegram(address)


def fc_read(address: int) -> fc_telegram.FcTelegram:
    return fc_telegram.read_parameter_request(1).telegram(address)


def control_word(server, address: int) -> int:
    with server.lock:
        return server.devices[address].model.control_word


def test_a_late_fc_reply_comes_after_the_timeout_and_the_line_is_served_meanwhile(fc_line):
    server, master = fc_line
    server.faults.inject(FC51, 'late')
    sent_s = master.send(fc_start(FC51))
    master.send(fc_read(VLT5000))
    master.send(fc_read(FC51))
    replies = master.replies(2)
    assert control_word(server, FC51) == START_WORD  # taken, not yet answered
    replies += master.replies(1)
    assert [(reply.unit, reply.kind) for reply in replies] == [
        (VLT5000, fc_telegram.LGE_PARAMETER), (FC51, fc_telegram.LGE_PARAMETER),
        (FC51, fc_telegram.LGE_PROCESS)]
    late = replies[2].at_s - sent_s
    assert late_by_s() <= late < late_by_s() + READ_TIMEOUT_S / 2, late
    assert server.faults.totals() == {'late': 1}


def test_a_late_batched_fc_reply_comes_just_before_the_next_reply(fc_line):
    server, master = fc_line
    server.faults.inject(FC51, 'late_batched')
    master.send(fc_start(FC51))
    assert wait_until(lambda: control_word(server, FC51) == START_WORD)
    assert master.quiet_for(QUIET_S), master.buffer
    next_sent_s = master.send(fc_read(VLT5000))
    replies = master.replies(2)
    assert [(reply.unit, reply.kind) for reply in replies] == [
        (FC51, fc_telegram.LGE_PROCESS), (VLT5000, fc_telegram.LGE_PARAMETER)]
    assert replies[0].at_s >= next_sent_s
    assert server.faults.totals() == {'late_batched': 1}


def test_a_slow_fc_reply_no_longer_holds_up_the_line(fc_line):
    server, master = fc_line
    server.faults.inject(FC51, 'slow')
    sent_s = master.send(fc_read(FC51))
    master.send(fc_read(VLT5000))
    replies = master.replies(2)
    assert [reply.unit for reply in replies] == [VLT5000, FC51]
    assert replies[1].at_s - sent_s >= SLOW_S


# -- AP ASCII -----------------------------------------------------------------------------
@pytest.fixture
def ascii_line():
    """Serve MCD 500s at 20 and 21 on an AP ASCII line; yield the server and a raw master."""
    server = make_ap_ascii_server({MCD_A: 'mcd500', MCD_B: 'mcd500'}, start_time_s=5.0)
    time_late_replies(server)
    server.open_pty()
    server.start()
    master = RawMaster.on_pty(server.pty_path, AsciiCodec())
    yield server, master
    master.close()
    server.stop()


ACK, DATA = ap_ascii.ACK, ap_ascii.STX


def address(unit: int) -> bytes:
    return ap_ascii.address_fragment(unit)


def message(code: str) -> bytes:
    return ap_ascii.message_fragment(code)


def exchange(master: RawMaster, unit: int, code: str) -> List[Reply]:
    """Send an address fragment, take its ACK, send the message; return both replies."""
    master.send(address(unit))
    acked = master.replies(1)
    master.send(message(code))
    return acked + master.replies(1)


def ascii_state(server, unit: int) -> int:
    with server.lock:
        server.devices[unit].advance(time.monotonic())
        return server.devices[unit].state


def test_ap_ascii_b10_executes_at_once_and_its_ack_comes_late(ascii_line):
    server, master = ascii_line
    server.inject(MCD_A, 'late', fragment='message')
    master.send(address(MCD_A))
    assert master.replies(1)[0].kind == ACK  # the address is ACKed as usual
    sent_s = master.send(message('B10'))
    assert [reply.kind for reply in exchange(master, MCD_B, 'C22')] == [ACK, DATA]
    assert [reply.kind for reply in exchange(master, MCD_A, 'C22')] == [ACK, DATA]
    assert ascii_state(server, MCD_A) == STARTING  # B10 was executed, not yet ACKed
    late, = master.replies(1)
    assert late.kind == ACK and late_by_s() <= late.at_s - sent_s < READ_TIMEOUT_S / 2
    assert server.faults.totals() == {'late': 1}
    assert master.quiet_for(QUIET_S), master.buffer


def test_ap_ascii_a_late_address_ack_comes_after_the_other_exchanges(ascii_line):
    server, master = ascii_line
    server.inject(MCD_A, 'late')  # fragment='address'
    sent_s = master.send(address(MCD_A))
    assert wait_until(lambda: server.faults.totals() == {'late': 1})
    assert [reply.kind for reply in exchange(master, MCD_B, 'C22')] == [ACK, DATA]
    late, = master.replies(1)
    assert late.kind == ACK and late.at_s - sent_s >= late_by_s()


def test_ap_ascii_a_late_batched_reply_comes_just_before_the_next_fragments_answer(
        ascii_line):
    server, master = ascii_line
    server.inject(MCD_A, 'late_batched', fragment='message')
    master.send(address(MCD_A))
    assert master.replies(1)[0].kind == ACK
    master.send(message('B10'))
    assert wait_until(lambda: ascii_state(server, MCD_A) == STARTING)
    assert master.quiet_for(QUIET_S), master.buffer
    server.inject(MCD_A, 'late_batched', fragment='message')
    assert [reply.kind for reply in exchange(master, MCD_A, 'C22')] == [ACK, ACK]  # B10's
    assert master.quiet_for(QUIET_S), master.buffer  # the status is held in turn
    next_sent_s = master.send(address(MCD_B))
    held, acked = master.replies(2)
    assert (held.kind, acked.kind) == (DATA, ACK) and held.at_s >= next_sent_s
    assert server.faults.totals() == {'late_batched': 2}


def test_ap_ascii_a_slow_reply_no_longer_holds_up_the_line(ascii_line):
    server, master = ascii_line
    server.inject(MCD_A, 'slow', fragment='message')
    master.send(address(MCD_A))
    assert master.replies(1)[0].kind == ACK
    sent_s = master.send(message('C22'))
    master.send(address(MCD_B))
    acked, slow = master.replies(2)
    assert (acked.kind, slow.kind) == (ACK, DATA) and slow.at_s - sent_s >= SLOW_S


def test_ap_ascii_inject_names_its_fragments():
    server = make_ap_ascii_server({MCD_A: 'mcd500'})
    with pytest.raises(ValueError, match='allowed address, message'):
        server.inject(MCD_A, 'late', fragment='ack')
    with pytest.raises(ValueError, match='allowed nak, bel'):
        server.inject(MCD_A, 'crc')


# -- drive_bridge_sim ---------------------------------------------------------------------
def sim_server(*argv: str):
    return sim_cli.build_server(sim_cli.build_parser().parse_args(list(argv)))


def test_the_simulator_cli_takes_the_late_timing_for_random_and_console_faults():
    timing = ('--fault-late', '0.05', '--master-timeout', '0.3')
    server = sim_server('--device', 'mcd500:20', '--faults', '0.2:late,late_batched', *timing)
    assert server.faults.plan == FaultPlan(0.2, ('late', 'late_batched'), 1, 0.1,
                                           late_s=0.05, master_timeout_s=0.3)
    assert sim_server('--device', 'mcd500:20', '--faults', '0.1').faults.plan == FaultPlan(
        0.1, MODBUS_FAULTS, late_s=0.02, master_timeout_s=0.5)  # every kind, the defaults
    server = sim_server('--device', 'mcd500:20', '--device', 'mcd202:21', *timing)
    assert server.faults.plan == FaultPlan(0.0, MODBUS_FAULTS, late_s=0.05,
                                           master_timeout_s=0.3)  # for the console's faults
    server.open_pty()
    server.start()
    master = RawMaster.on_pty(server.pty_path, RtuCodec())
    try:
        assert 'mcd500' in sim_cli.run_console_command(server, 'fault 20 late')
        sent_s = master.send(start_request())
        reply, = master.replies(1)
        assert reply.kind == rtu.WRITE_SINGLE_REGISTER and reply.at_s - sent_s >= 0.35
        assert 'mcd500' in sim_cli.run_console_command(server, 'fault 20 late_batched 1')
        master.send(status_request(MCD_A))
        assert wait_until(lambda: server.faults.totals() == {'late': 1, 'late_batched': 1})
        master.send(status_request(MCD_B))
        assert [reply.unit for reply in master.replies(2)] == [MCD_A, MCD_B]
        answer = sim_cli.run_console_command(server, 'fault 20 late:message')
        assert answer.startswith("error: 'late:message': a fragment (:address, :message) is "
                                 'for AP ASCII only'), answer
    finally:
        master.close()
        server.stop()


def test_the_simulator_console_puts_an_ap_ascii_fault_on_the_message_fragment():
    server = sim_server('--protocol', 'ap_ascii', '--device', 'mcd500:20', '--fault-late',
                        '0.05', '--master-timeout', '0.3')
    server.open_pty()
    server.start()
    master = RawMaster.on_pty(server.pty_path, AsciiCodec())
    try:
        answer = sim_cli.run_console_command(server, 'fault 20 late:nope')
        assert "unknown fragment 'nope': allowed address, message" in answer, answer
        assert 'mcd500' in sim_cli.run_console_command(server, 'fault 20 late:message')
        master.send(address(MCD_A))
        assert master.replies(1)[0].kind == ACK
        sent_s = master.send(message('B10'))
        reply, = master.replies(1)
        assert reply.kind == ACK and reply.at_s - sent_s >= 0.35
        assert ascii_state(server, MCD_A) == STARTING
    finally:
        master.close()
        server.stop()


@pytest.mark.parametrize('argv, reason', [
    (['--fault-late', '-0.1'], "argument --fault-late: '-0.1': give seconds, 0 or more"),
    (['--master-timeout', 'soon'], "argument --master-timeout: 'soon' is not a number"),
    (['--master-timeout', 'nan'], "argument --master-timeout: 'nan': give seconds"),
    (['--fault-slow', '-1'], "argument --fault-slow: '-1': give seconds"),
])
def test_bad_late_timing_is_refused_in_one_line(argv, reason, capsys):
    with pytest.raises(SystemExit) as exited:
        sim_cli.build_parser().parse_args(['--device', 'mcd500:20', *argv])
    error = capsys.readouterr().err
    assert exited.value.code == 2 and error.count('\n') == 1, error
    assert error.startswith('drive_bridge_sim: error: ') and reason in error, error


def test_a_plan_with_negative_late_timing_is_refused():
    with pytest.raises(ValueError, match=r'late_s must not be negative \(-0.1\)'):
        FaultInjector(MODBUS_FAULTS).set_plan(FaultPlan(late_s=-0.1))
    with pytest.raises(ValueError, match='master_timeout_s must not be negative'):
        parse_fault_plan('0.1', MODBUS_FAULTS, master_timeout_s=-1.0)
