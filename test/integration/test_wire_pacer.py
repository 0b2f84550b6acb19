"""
The wire pacer between real masters and the simulators on ptys.

Wall-clock checks are floors (the pacer must never deliver sooner than the wire could) and
generous ceilings on the best of several runs, so that they hold on a loaded machine.
"""

from contextlib import contextmanager
import os
import signal
import subprocess
import sys
import time

from drive_bridge.bus.master import BusMaster, BusTiming, DeviceSpec
from drive_bridge.devices.mcd import McdProfile
from drive_bridge.protocol import rtu
from drive_bridge.protocol.crc import crc_ok
from drive_bridge.protocol.requests import AsciiRequest, ReadRegisters
from drive_bridge.sim.ap_ascii_server import make_ap_ascii_server
from drive_bridge.sim.mcd_device import make_mcd_server
from drive_bridge.sim.wire_pacer import (
    COLLISION, GAP_VIOLATION, LineTiming, MASTER, OK, SLAVE, transactions, wire_fraction,
    WirePacer)
from drive_bridge.transport.ap_ascii import ApAsciiTransport
from drive_bridge.transport.link import LinkSettings
from drive_bridge.transport.serial_rtu import RtuSerialTransport
from integration_helpers import wait_until
import pytest
import serial

# The pacer and the simulator behind it hand bytes on at wire time (36 ms a character at
# 300 baud): beside other test processes a held-up thread broke a frame.
pytestmark = pytest.mark.realtime

REQUEST = rtu.read_registers_request(20, 2, 6).encode()  # 8 bytes; the reply has 17
REPLY_BYTES = 17


@contextmanager
def paced_line(server, timing: LineTiming, link_path: str = '', ideal_slave: bool = False):
    """Serve ``server`` on a pty behind a pacer; yield the pacer (its pty is for the master)."""
    server.open_pty()
    server.start()
    pacer = WirePacer(timing, ideal_slave=ideal_slave)
    try:
        pacer.open_pty(server.pty_path, link_path)
        pacer.start()
        yield pacer
    finally:
        pacer.stop()
        server.stop()


@contextmanager
def rtu_master(path: str, baudrate: int, timeout_s: float):
    """Yield the native RTU engine on ``path`` (a pty: parity N, the timing is the pacer's)."""
    transport = RtuSerialTransport(LinkSettings(port=path, baudrate=baudrate, parity='N',
                                                timeout_s=timeout_s))
    transport.connect()
    try:
        yield transport
    finally:
        transport.close()


def test_transactions_take_their_wire_time_and_the_log_shows_them():
    timing = LineTiming(9600, 'E', 1)
    server = make_mcd_server({20: 'mcd500'})
    with paced_line(server, timing) as pacer, \
            rtu_master(pacer.path, 9600, 0.5) as master:
        durations = []
        for _ in range(10):
            started = time.monotonic()
            assert len(master.execute(20, ReadRegisters(2, 6))) == 6
            durations.append(time.monotonic() - started)
            time.sleep(timing.gap_s)  # the master keeps the gap
        frames = pacer.frames()
        counters = pacer.counters()
    # Request, gap, reply: never sooner than the wire; a pty alone takes about 1 ms.
    least_s = (8 + REPLY_BYTES) * timing.char_s + timing.gap_s
    assert least_s == pytest.approx(0.0326, abs=1e-4)
    assert min(durations) >= least_s - 1e-4
    assert min(durations) < least_s + 0.025
    assert [frame.sender for frame in frames] == [MASTER, SLAVE] * 10
    assert all(frame.fate == OK for frame in frames)
    for request, reply in transactions(frames):
        assert request.data == REQUEST
        assert len(reply.data) == REPLY_BYTES and crc_ok(reply.data) and reply.data[0] == 20
        assert request.end_s - request.start_s == pytest.approx(8 * timing.char_s)
        assert reply.end_s - reply.start_s == pytest.approx(REPLY_BYTES * timing.char_s)
        assert reply.start_s - request.end_s >= timing.gap_s - 1e-9
    for reply, request in zip(frames[1::2], frames[2::2]):
        assert request.start_s - reply.end_s >= timing.gap_s - 1e-9
    assert counters.frames == {MASTER: 10, SLAVE: 10}
    assert (counters.gap_violations, counters.collisions, counters.lost_frames) == (0, 0, 0)
    assert server.stats.requests == 10


IDEAL_SLAVE = pytest.mark.parametrize('ideal_slave', [False, True], ids=['rtu_slave', 'ideal'])


@IDEAL_SLAVE
def test_a_master_without_the_gap_gets_no_answer(ideal_slave):
    # 300 baud: a 128 ms gap, so that even a pacer slowed by a loaded machine sees that the
    # second request follows the reply at once. The bridge's transports keep the gap
    # themselves (the end-of-frame silence), so the master here is a bare port.
    timing = LineTiming(300, 'E', 1)
    server = make_mcd_server({20: 'mcd500'})
    with paced_line(server, timing, ideal_slave=ideal_slave) as pacer, \
            serial.Serial(pacer.path, 300, timeout=3.0) as port:
        port.write(REQUEST)
        assert len(port.read(REPLY_BYTES)) == REPLY_BYTES
        port.write(REQUEST)  # sent the moment the reply was in
        port.timeout = 2.0
        assert port.read(REPLY_BYTES) == b''
        time.sleep(timing.gap_s)
        port.timeout = 3.0
        port.write(REQUEST)  # with the gap it is answered again
        assert len(port.read(REPLY_BYTES)) == REPLY_BYTES
        frames = pacer.frames()
        counters = pacer.counters()
    assert [frame.fate for frame in frames] == [OK, OK, GAP_VIOLATION, OK, OK]
    assert counters.gap_violations == 1 and counters.frames == {MASTER: 3, SLAVE: 2}
    assert server.stats.requests == 2  # the glued request never reached the slave


def run_bus(path: str, baudrate: int, gap_s: float, polls: int) -> tuple:
    """Poll one MCD until ``polls`` polls succeeded; return (seconds, failed transactions)."""
    transport = RtuSerialTransport(LinkSettings(port=path, baudrate=baudrate, parity='N',
                                                timeout_s=0.5))
    spec = DeviceSpec('soft', 20, McdProfile('mcd500'), poll_rate_hz=100.0)
    bus = BusMaster(transport, [spec], BusTiming(frame_gap_s=gap_s, offline_after=100))
    bus.run_once()  # connect
    started = time.monotonic()
    try:
        while True:
            bus.run_step()
            stats = bus.snapshot('soft').stats
            failed = int(stats['errors'])
            if int(stats['transactions']) - failed >= polls:
                return time.monotonic() - started, failed
    finally:
        bus.shutdown(stop_motors=False)


@IDEAL_SLAVE
def test_the_transport_keeps_the_gap_whatever_gap_the_bus_is_given(ideal_slave):
    # A bus given no frame gap of its own (frame_gap_s 0) still never glues a request to the
    # reply before it: the line discipline waits the inter-frame silence after every reply
    # (the end-of-frame check) before it returns, and the bus counts it towards its gap.
    timing = LineTiming(4800, 'E', 1)
    with paced_line(make_mcd_server({20: 'mcd500'}), timing, ideal_slave=ideal_slave) as pacer:
        _, kept_failures = run_bus(pacer.path, 4800, timing.gap_s, 6)
        _, zero_gap_failures = run_bus(pacer.path, 4800, 0.0, 6)
        counters = pacer.counters()
    assert (kept_failures, zero_gap_failures) == (0, 0)
    assert counters.gap_violations == 0 and counters.collisions == 0


@IDEAL_SLAVE
def test_a_paced_bus_never_beats_the_wire(ideal_slave):
    timing = LineTiming(19200, 'E', 1)
    server = make_mcd_server({20: 'mcd500', 21: 'mcd500'})
    with paced_line(server, timing, ideal_slave=ideal_slave) as pacer:
        transport = RtuSerialTransport(LinkSettings(port=pacer.path, baudrate=19200,
                                                    parity='N', timeout_s=0.2))
        specs = [DeviceSpec(f'd{unit}', unit, McdProfile('mcd500'), poll_rate_hz=100.0)
                 for unit in (20, 21)]
        bus = BusMaster(transport, specs, BusTiming(frame_gap_s=timing.gap_s))
        bus.run_once()
        started = time.monotonic()
        while time.monotonic() - started < 1.0:
            bus.run_step()
        bus.shutdown(stop_motors=False)
        frames = [frame for frame in pacer.frames() if frame.start_s >= started]
    ended = max(frame.end_s for frame in frames)
    pairs = transactions(frames)
    assert len(pairs) >= 10
    fraction = wire_fraction(pairs, timing, ended - min(f.start_s for f in frames) +
                             timing.gap_s)
    assert 0.2 < fraction <= 1.0
    assert all(reply.start_s - request.end_s >= timing.gap_s - 1e-6 for request, reply in pairs)


def test_a_request_sent_while_the_reply_is_on_the_wire_collides():
    timing = LineTiming(300, 'E', 1)  # the reply is on the wire for 623 ms
    server = make_mcd_server({20: 'mcd500'})
    with paced_line(server, timing) as pacer, \
            serial.Serial(pacer.path, 300, timeout=1.5) as port:
        port.write(REQUEST)
        assert wait_until(lambda: any(f.sender == SLAVE for f in pacer.frames()), 2.0,
                          interval_s=0.001)
        port.write(REQUEST)  # the master talks over the reply
        received = port.read(REPLY_BYTES)
        frames = pacer.frames()
        counters = pacer.counters()
    assert [(frame.sender, frame.fate) for frame in frames] == \
        [(MASTER, OK), (SLAVE, COLLISION), (MASTER, COLLISION)]
    assert counters.collisions == 1 and counters.lost_frames == 2
    assert len(received) < REPLY_BYTES  # the reply was cut at the collision
    assert server.stats.requests == 1


def test_the_master_may_open_the_pacer_through_a_symlink(tmp_path):
    link = str(tmp_path / 'ttyPACED')
    timing = LineTiming(19200, 'E', 1)
    with paced_line(make_mcd_server({20: 'mcd500'}), timing, link) as pacer, \
            rtu_master(link, 19200, 0.5) as master:
        assert os.path.realpath(link) == pacer.path
        assert len(master.execute(20, ReadRegisters(2, 6))) == 6
    assert not os.path.lexists(link)


def test_ap_ascii_through_the_pacer_without_the_gap_rule():
    timing = LineTiming(9600, 'N', 1, gap_rule=False)  # AP ASCII is 8N1: 10 bits
    server = make_ap_ascii_server({20: 'mcd500'})
    with paced_line(server, timing) as pacer:
        transport = ApAsciiTransport(LinkSettings(protocol='ap_ascii', port=pacer.path,
                                                  parity='N', timeout_s=0.5))
        transport.connect()
        try:
            started = time.monotonic()
            assert transport.execute(20, AsciiRequest('C22', 'status')) & 0x0F == 1  # ready
            elapsed_s = time.monotonic() - started
        finally:
            transport.close()
        frames = pacer.frames()
        counters = pacer.counters()
    # Address, ACK, request, reply: each waits for the one before.
    assert [frame.sender for frame in frames] == [MASTER, SLAVE, MASTER, SLAVE]
    assert frames[0].data == b'\x04209A\x05' and frames[1].data == b'\x06'
    assert frames[2].data == bytes.fromhex('02 43 32 32 35 37 03')  # C22, a worked frame
    assert all(frame.fate == OK for frame in frames)
    total_bytes = sum(len(frame.data) for frame in frames)
    assert elapsed_s >= total_bytes * timing.char_s - 1e-4
    assert counters.gap_violations == 0 and counters.collisions == 0


def test_the_simulator_cli_puts_a_pacer_in_front_of_its_pty(tmp_path):
    link = str(tmp_path / 'ttyPACED')
    simulator = subprocess.Popen(
        [sys.executable, '-m', 'drive_bridge.sim.cli', '--device', 'mcd500:20', '--pace',
         '9600:E:1', '--link', link], stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
        text=True)
    try:
        lines = []
        for line in simulator.stdout:
            lines.append(line.strip())
            if line.startswith('ready:'):
                break
        assert 'paced: 9600 baud 8E1 (11 bits), gap rule on' in lines
        assert f'link: {link}' in lines
        timing = LineTiming(9600, 'E', 1)
        with rtu_master(link, 9600, 0.5) as master:
            started = time.monotonic()
            assert len(master.execute(20, ReadRegisters(2, 6))) == 6
            assert time.monotonic() - started >= 25 * timing.char_s + timing.gap_s - 1e-4
    finally:
        simulator.send_signal(signal.SIGTERM)
        output = simulator.communicate(timeout=10)[0]
    assert simulator.returncode == 0
    assert 'line: 1 frames from the master, 1 from the devices, 0 gap violations, ' \
        '0 collisions' in output
