"""The simulator's serving loop wakes for bytes, due replies and stale partial frames only."""

import os
import select
import socket
import time

from drive_bridge.protocol import rtu
from drive_bridge.sim.mcd_device import make_mcd_server
from integration_helpers import wait_until
import pytest

UNIT = 20
QUIET_S = 0.5
# Wakes allowed in QUIET_S: the stale partial frame's one, and a few for the bytes (the loop
# polled every 5 ms before: 100 in QUIET_S; a kept partial frame made it spin: thousands).
MAX_WAKES = 10


@pytest.fixture
def server():
    server = make_mcd_server({UNIT: 'mcd500'})
    server.open_pty()
    server.open_tcp(framing='mbap')
    server.start()
    yield server
    server.stop()


def count_waits(server) -> list:
    """Count the serving loop's waits in its selector from now on (one a wake-up)."""
    count = [0]
    selector = server.line._selector
    original = selector.select

    def select(timeout=None):
        count[0] += 1
        return original(timeout)
    selector.select = select
    return count


def test_an_idle_simulator_does_not_wake(server):
    time.sleep(0.1)  # the loop is in its wait
    waits = count_waits(server)
    time.sleep(QUIET_S)
    assert waits[0] <= 1, waits


def test_a_partial_rtu_frame_is_dropped_once_stale_then_the_loop_waits(server):
    request = rtu.read_registers_request(UNIT, 2, 6).encode()
    fd = os.open(server.pty_path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    try:
        waits = count_waits(server)
        os.write(fd, request[:4])  # half a request
        time.sleep(QUIET_S)
        assert waits[0] <= MAX_WAKES, waits
        os.write(fd, request)  # answered: not glued to the stale half
        reply = b''
        deadline = time.monotonic() + 2.0
        while len(reply) < 17 and time.monotonic() < deadline:
            if select.select([fd], [], [], 0.1)[0]:
                reply += os.read(fd, 64)
        assert reply[:2] == bytes([UNIT, 3]) and len(reply) == 17, reply.hex()
    finally:
        os.close(fd)


def test_a_partial_mbap_frame_kept_does_not_make_the_loop_spin(server):
    with socket.create_connection(('127.0.0.1', server.tcp_port), timeout=2.0) as client:
        assert wait_until(lambda: len(server.line._selector.get_map()) >= 4)  # accepted
        waits = count_waits(server)
        client.sendall(bytes([0, 1, 0]))  # three bytes of an MBAP header: kept, incomplete
        time.sleep(QUIET_S)
        assert waits[0] <= MAX_WAKES, waits
