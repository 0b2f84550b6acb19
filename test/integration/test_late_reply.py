"""
A late reply that reaches the master together with the reply asked for (issue 27).

A device (or the simulator, starved on a loaded machine) answers request A only after the
master gave up on it and sent request B; both replies then arrive at once. Seen beside a CPU
hog: the simulator's thread read four requests in one read after 1.1 s and answered them
back to back. The reply asked for must be taken, and a late reply must never be taken for
it. The cases marked xfail are known defects (strict: they fail the run once fixed, so the
mark comes off with the fix).
"""

import os
import threading

from drive_bridge.errors import TransportError
from drive_bridge.protocol import rtu
from drive_bridge.protocol.requests import ReadRegisters, WriteRegister
from drive_bridge.sim.pty_link import PtyLink
from drive_bridge.transport.engines import make_transport
from drive_bridge.transport.link import LinkSettings
from drive_bridge.transport.protocols import SERIAL_ENGINES
import pytest

TIMEOUT_S = 0.3


def read_request(fd: int) -> rtu.RtuFrame:
    """Return the next whole request read from the pty master ``fd``."""
    buffer = b''
    while True:
        buffer += os.read(fd, 256)
        result = rtu.decode_request(buffer)
        if result.frame is not None:
            return result.frame


def answer(frame: rtu.RtuFrame) -> bytes:
    """Return a device's reply: registers 100 * address + i, or a write's echo."""
    if frame.function == rtu.READ_HOLDING_REGISTERS:
        address, count = rtu.parse_address_count(frame.data)
        return rtu.registers_response(
            frame.unit, frame.function, [address * 100 + i for i in range(count)]).encode()
    return frame.encode()


def late_device(fd: int) -> None:
    """Withhold the reply to the first request; send it with the second one's reply."""
    late = read_request(fd)
    asked = read_request(fd)
    os.write(fd, answer(late) + answer(asked))


def run_pair(engine: str, first, second):
    """Run two transactions, the first one's reply late; return the second one's outcome."""
    pty = PtyLink()
    os.set_blocking(pty.master, True)
    device = threading.Thread(target=late_device, args=(pty.master,), daemon=True)
    device.start()
    transport = make_transport(LinkSettings(port=pty.path, parity='N', timeout_s=TIMEOUT_S),
                               {'serial_engine': engine})
    transport.connect()
    try:
        with pytest.raises(TransportError, match='no reply'):
            transport.execute(*first)
        try:
            return transport.execute(*second)
        except TransportError as error:
            return error
    finally:
        transport.close()
        device.join(2.0)
        pty.close()


def known_defect(engine: str, defective: tuple, reason: str):
    """Return ``engine`` as a parameter: xfail (strict) where the defect is known."""
    marks = [pytest.mark.xfail(strict=True, reason=reason)] if engine in defective else []
    if engine == 'pymodbus':
        marks.append(pytest.mark.pymodbus)
    return pytest.param(engine, marks=marks, id=engine)


OTHER_UNIT = [known_defect(engine, ('pymodbus',),
                           "pymodbus's RTU framer consumes every byte read with the first "
                           'frame and skips it for its unit: the reply asked for is lost')
              for engine in SERIAL_ENGINES]
SAME_UNIT = [known_defect(engine, SERIAL_ENGINES,
                          'RTU has no transaction id: a late reply of the same unit, '
                          'function and length is taken for the one asked for')
             for engine in SERIAL_ENGINES]


@pytest.mark.parametrize('engine', OTHER_UNIT)
def test_a_write_answered_behind_another_units_late_reply_is_done(engine):
    """A write the device executed and answered is not reported failed (nor resent)."""
    outcome = run_pair(engine, (21, ReadRegisters(2, 6)), (20, WriteRegister(0, 1)))
    assert outcome is None, outcome


@pytest.mark.parametrize('engine', SAME_UNIT)
def test_a_late_reply_of_the_same_unit_is_never_taken_as_current_values(engine):
    """The late reply to a read of registers 2-7 is not the reply to a read of 10-15."""
    outcome = run_pair(engine, (20, ReadRegisters(2, 6)), (20, ReadRegisters(10, 6)))
    assert outcome == [1000 + i for i in range(6)] or isinstance(outcome, TransportError), \
        f'stale values taken as current: {outcome}'
