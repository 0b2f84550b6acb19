"""The native RTU engine (and Modbus TCP through pymodbus) against the simulated MCD module."""

import contextlib
import logging
import os
import select
import sys
import threading
import time
import tty
from typing import Callable, Optional

from drive_bridge.errors import BadFrame, CrcError, DeviceException, LinkDown, NoResponse
from drive_bridge.protocol import rtu
from drive_bridge.protocol.requests import ReadRegisters, WriteRegister
from drive_bridge.sim.mcd_device import make_mcd_server as make_server
from drive_bridge.transport import serial_port
from drive_bridge.transport.engines import make_transport
from drive_bridge.transport.link import LinkSettings, port_framing, PortFraming
from drive_bridge.transport.serial_port import direct_descriptor
import pytest
import serial

MCD500_PRODUCT = (7 << 3) | 1


def transport_for(settings):
    transport = make_transport(settings)
    transport.connect()
    return transport


@pytest.fixture
def pty_transport(sim_bus):
    transport = transport_for(LinkSettings(port=sim_bus.pty_path, parity='N', timeout_s=0.2))
    yield transport
    transport.close()


def test_read_status_block_and_write_command(pty_transport, sim_bus):
    registers = pty_transport.execute(20, ReadRegisters(2, 6))
    assert registers[0] & 0x0F == 1 and registers[4] == MCD500_PRODUCT
    assert pty_transport.execute(20, WriteRegister(1, 1)) is None
    assert list(sim_bus.devices[20].model.commands_received) == [1]


@pytest.mark.realtime  # a bound on the time a silent address holds the line
def test_a_silent_address_holds_the_line_for_one_timeout_and_the_guard(sim_bus):
    # The quarantine after a transaction without a reply waits for late replies for the
    # guard (late_reply_guard, Modbus RTU's own 0.1 s here), then the next request goes.
    transport = transport_for(LinkSettings(port=sim_bus.pty_path, parity='N', timeout_s=1.0))
    try:
        started = time.monotonic()
        with pytest.raises(NoResponse, match='no reply within 1 s'):
            transport.execute(22, ReadRegisters(2, 1))
        held_s = time.monotonic() - started
        assert transport.execute(20, ReadRegisters(2, 1))  # the line works on
    finally:
        transport.close()
    assert 1.05 < held_s < 1.7, held_s


@pytest.mark.parametrize('transaction, code', [
    (ReadRegisters(2, 7), 5), (ReadRegisters(1, 1), 3), (WriteRegister(1, 9), 6),
    (WriteRegister(3, 1), 4), (ReadRegisters(8 + 591, 1), 7)])
def test_module_error_codes_come_back_as_device_exceptions(pty_transport, transaction, code):
    with pytest.raises(DeviceException) as error:
        pty_transport.execute(20, transaction)
    assert error.value.code == code


def test_hand_on_refusal_is_error_09(pty_transport, sim_bus):
    sim_bus.devices[20].model.hand_on = True
    with pytest.raises(DeviceException) as error:
        pty_transport.execute(20, WriteRegister(1, 1))
    assert error.value.code == 9
    assert pty_transport.execute(20, ReadRegisters(2, 6))[0] & 0x0F == 1


def test_unserved_address_is_silent(pty_transport, sim_bus):
    started = time.monotonic()
    with pytest.raises(NoResponse):
        pty_transport.execute(22, ReadRegisters(2, 6))
    elapsed = time.monotonic() - started
    assert 0.25 < elapsed < 1.1  # one timeout and the guard (0.1 s)
    assert sim_bus.stats.unserved == 1
    assert pty_transport.execute(21, ReadRegisters(2, 6))[4] == (4 << 3) | 1


def test_corrupted_reply_is_a_bad_frame(pty_transport, sim_bus):
    sim_bus.reply_hook = lambda unit, data: data[:-1] + bytes([data[-1] ^ 0xFF])
    with pytest.raises(CrcError):
        pty_transport.execute(20, ReadRegisters(2, 6))
    sim_bus.reply_hook = None
    assert pty_transport.execute(20, ReadRegisters(2, 6))


def test_a_pty_with_parity_e_opens_every_time_and_the_log_says_why_once(
        sim_bus, tmp_path, caplog):
    # Linux clears the parity a pty client asks for and refuses the next open that asks
    # again (EINVAL): the node restarted, or the CLI run again after a scan, found the
    # simulator's pty "invalid". The pty is opened without parity; the timing stays 8E1.
    caplog.set_level(logging.INFO, logger='drive_bridge')
    link = tmp_path / 'ttyLINK'  # through a symlink, as drive_bridge_sim --link makes it
    link.symlink_to(sim_bus.pty_path)
    settings = LinkSettings(port=str(link), parity='E', timeout_s=0.3)
    for transport_number in range(2):  # a node started twice
        transport = make_transport(settings)
        for _ in range(3):  # reconnects of one node
            transport.connect()
            assert transport.execute(20, ReadRegisters(2, 6))[4] == MCD500_PRODUCT
            transport.close()
    notes = [record for record in caplog.records if record.name.startswith('drive_bridge')]
    assert [record.levelno for record in notes] == [logging.INFO] * 2, caplog.text
    assert notes[0].getMessage() == (
        f'{link} ({sim_bus.pty_path}) is a pty: opened without parity (a pty has no wire, so '
        'no parity); timing as configured, 9600 baud 8E1')
    assert settings.effective_stopbits == 1 and settings.frame_gap_s == \
        rtu.frame_gap_s(9600, 'E', 1)


def test_the_native_engine_opens_a_pty_8n1_for_8e1_and_keeps_the_8e1_character_time(sim_bus):
    settings = LinkSettings(port=sim_bus.pty_path, parity='E', timeout_s=0.3)
    transport = make_transport(settings)
    framing = port_framing(settings)
    assert framing[:2] == ('N', 1)  # stopbits 0 means 1 for parity E, on a pty too
    assert transport.discipline.timing.char_s == rtu.character_time_s(9600, 'E', 1)
    assert not transport.discipline.timing.paced  # a pty: no timing evidence
    assert port_framing(LinkSettings(port=sim_bus.pty_path, parity='N')) == PortFraming('N', 2)


def test_missing_port_is_link_down_with_its_name():
    transport = make_transport(LinkSettings(port='/dev/ttyDOESNOTEXIST'))
    with pytest.raises(LinkDown, match='bus offline: /dev/ttyDOESNOTEXIST not found'):
        transport.connect()


def test_native_engine_garbage_wrong_address_and_truncation(sim_bus):
    transport = transport_for(LinkSettings(port=sim_bus.pty_path, parity='N', timeout_s=0.2))
    try:
        for hook, text in (
                # a valid frame of another unit is skipped (a late reply of unit 21)
                (lambda unit, data: rtu.RtuFrame(21, 3, data[2:-2]).encode(),
                 'no reply from address 20 within 0.2 s; 1 frame of other units'),
                (lambda unit, data: data[:6], 'truncated reply: 6 of 17 bytes'),
                # fewer than the 5 bytes the first wait asks the kernel for
                (lambda unit, data: data[:3], 'truncated reply: 3 of 17 bytes'),
                (lambda unit, data: b'\xff\xff\xff', r'invalid reply \(ff ff ff\)')):
            sim_bus.reply_hook = hook
            with pytest.raises(BadFrame, match=text):
                transport.execute(20, ReadRegisters(2, 6))
        sim_bus.reply_hook = None
        assert transport.execute(20, ReadRegisters(2, 6))[4] == MCD500_PRODUCT
    finally:
        transport.close()


@pytest.mark.parametrize('framing, protocol', [
    pytest.param('mbap', 'modbus_tcp', marks=pytest.mark.pymodbus),  # through pymodbus
    ('rtu', 'rtu_over_tcp')])
def test_tcp_protocols(framing, protocol):
    server = make_server({20: 'mcd500'})
    port = server.open_tcp(framing=framing)
    server.start()
    try:
        transport = transport_for(LinkSettings(protocol=protocol, tcp_port=port,
                                               timeout_s=0.3))
        assert transport.execute(20, ReadRegisters(2, 6))[4] == MCD500_PRODUCT
        with pytest.raises(NoResponse):  # gateway: exception 0Bh; RTU over TCP: silence
            transport.execute(23, ReadRegisters(2, 6))
        transport.close()
    finally:
        server.stop()


@pytest.mark.parametrize('parity', ['E', 'O'])
def test_even_and_odd_parity_serial_settings_over_socket_url(parity):
    # A pty rejects parity E/O; pyserial's socket:// carries the serial client's settings
    # to an RTU-over-TCP server instead.
    server = make_server({20: 'mcd500'})
    port = server.open_tcp(framing='rtu')
    server.start()
    try:
        transport = transport_for(LinkSettings(port=f'socket://127.0.0.1:{port}',
                                               parity=parity, timeout_s=0.3))
        assert transport.settings.effective_stopbits == 1
        assert transport.execute(20, ReadRegisters(2, 6))[4] == MCD500_PRODUCT
        transport.close()
    finally:
        server.stop()


def test_native_engine_reads_a_local_port_by_its_descriptor_and_a_url_through_pyserial(
        sim_bus):
    local = serial.Serial(sim_bus.pty_path, timeout=0)
    url = serial.serial_for_url('loop://', timeout=0)
    try:
        assert direct_descriptor(local) == local.fileno()
        assert direct_descriptor(url) is None
    finally:
        local.close()
        url.close()


def fill_until_it_takes_nothing(fd: int) -> None:
    """Write to ``fd`` until it has taken nothing for 0.5 s (the kernel moves pty buffers)."""
    while True:
        try:
            while True:
                os.write(fd, bytes(4096))
        except BlockingIOError:
            pass
        _, writable, _ = select.select([], [fd], [], 0.5)
        if not writable:
            return


def test_a_port_that_takes_no_more_bytes_is_link_down_within_the_timeout():
    master_fd, slave_fd = os.openpty()
    tty.setraw(slave_fd)
    path = os.ttyname(slave_fd)
    transport = transport_for(LinkSettings(port=path, parity='N', timeout_s=0.3))
    try:
        filler = os.open(path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        fill_until_it_takes_nothing(filler)  # nobody reads the line
        started = time.monotonic()
        with pytest.raises(LinkDown, match='takes no more bytes'):
            transport.execute(20, ReadRegisters(2, 1))
        assert time.monotonic() - started < 3.0
        assert not transport.connected
    finally:
        transport.close()
        for fd in (master_fd, slave_fd, filler):
            os.close(fd)


class CountingSelect:
    """``select.select`` for the transport's module that counts the calls that may wait."""

    def __init__(self):
        self.waits = 0
        self._changed = threading.Condition()

    def select(self, *args):
        with self._changed:
            self.waits += args[3] > 0
            self._changed.notify_all()
        return select.select(*args)

    def wait_for_waits(self, count: int, timeout_s: float = 1.0) -> None:
        """Return once ``count`` calls that may wait have begun (or after ``timeout_s``)."""
        with self._changed:
            self._changed.wait_for(lambda: self.waits >= count, timeout_s)


def answer_one_request(fd: int, reply: bytes, pause_s: Optional[float],
                       before_byte: Callable[[int], None] = lambda index: None) -> None:
    """
    Read one request on a pty's master side, then answer it.

    With ``pause_s`` None all of ``reply`` is written in one go, else one byte at a time with
    ``pause_s`` and ``before_byte(index)`` before each.
    """
    select.select([fd], [], [], 5.0)
    os.read(fd, 256)
    if pause_s is None:
        os.write(fd, reply)
        return
    for index, byte in enumerate(reply):
        before_byte(index)
        time.sleep(pause_s)
        os.write(fd, bytes([byte]))


@contextlib.contextmanager
def native_transport_answered(reply: bytes, pause_s: Optional[float] = None,
                              before_byte: Callable[[int], None] = lambda index: None):
    """Yield the native engine on a pty whose other side answers one request with ``reply``."""
    master_fd, slave_fd = os.openpty()
    tty.setraw(master_fd)
    answer = threading.Thread(target=answer_one_request,
                              args=(master_fd, reply, pause_s, before_byte))
    transport = transport_for(LinkSettings(port=os.ttyname(slave_fd), parity='N',
                                           timeout_s=1.0))
    try:
        answer.start()
        yield transport
    finally:
        answer.join()
        transport.close()
        os.close(master_fd)
        os.close(slave_fd)


@pytest.mark.realtime
@pytest.mark.skipif(not sys.platform.startswith('linux'), reason='VMIN and select: Linux')
@pytest.mark.parametrize('pause_s', [0.0, 0.002])
def test_native_engine_wakes_twice_for_a_reply_however_its_bytes_arrive(pause_s, monkeypatch):
    # VMIN: the kernel reports the port readable once the 5 first bytes are there, then once
    # the rest is, not for every byte (nor every USB batch). The answer's first byte waits
    # for the transport's first wait to begin, its sixth for the second: on a loaded machine
    # the whole reply was once there before the transport looked (0 waits), which says
    # nothing about the wake-ups; an engine that woke for each byte still waits 17 times.
    # The third wait is the end-of-frame silence after the reply (no byte may follow it
    # within the inter-frame gap), which wakes once whatever the reply.
    reply = rtu.registers_response(20, 3, [1, 2, 3, 4, 5, 6]).encode()
    counting = CountingSelect()

    waits_before_byte = {0: 1, rtu.MIN_RESPONSE_BYTES: 2}

    def after_the_transport_waits(index: int) -> None:
        if index in waits_before_byte:
            counting.wait_for_waits(waits_before_byte[index])
    with native_transport_answered(reply, pause_s, after_the_transport_waits) as transport:
        monkeypatch.setattr(serial_port, 'select', counting)
        assert transport.execute(20, ReadRegisters(2, 6)) == [1, 2, 3, 4, 5, 6]
        assert counting.waits == 3


def test_a_byte_right_after_a_reply_makes_it_one_corrupt_frame():
    # A receiver ends a frame by the silence after it: a byte that continues the line within
    # the inter-frame gap makes the reply and the byte one corrupt frame (the Modbus serial
    # line spec), so not even a whole exception reply is taken; the line is quarantined.
    reply = rtu.exception_response(20, 3, 2).encode() + b'\x00'
    with native_transport_answered(reply) as transport:
        started = time.monotonic()
        with pytest.raises(BadFrame, match='one corrupt frame'):
            transport.execute(20, ReadRegisters(2, 6))
        # quarantined to the guard after the deadline: 1 s + 0.1 s, the device may answer
        assert time.monotonic() - started < 1.1 + 0.5
        assert transport.last_report.noise_bytes == 6
