"""Serial ports are opened exclusively: a second opener gets one line naming the owner."""

from drive_bridge.config import model as cfg
from drive_bridge.errors import LinkDown
from drive_bridge.protocol.requests import ReadCoils
from drive_bridge.sim.devices import make_sim_server
from drive_bridge.transport.port_owner import lock_holders
import pytest


@pytest.fixture
def line():
    server = make_sim_server({1: 'fc51'})
    server.open_pty()
    server.start()
    yield server
    server.stop()


def transport(line, protocol='modbus_rtu'):
    values = {'port': line.pty_path, 'parity': 'N', 'protocol': protocol, 'devices': ['a']}
    family = {'modbus_rtu': 'fc', 'ap_ascii': 'mcd', 'fc_protocol': 'fc'}[protocol]
    config = cfg.build_config(values, {'a': {'family': family, 'address': 1, 'model': 'auto'}})
    return config.make_transport()


OPENERS = ('modbus_rtu', 'ap_ascii', 'fc_protocol')


@pytest.mark.parametrize('first', OPENERS)
@pytest.mark.parametrize('second', OPENERS)
def test_a_second_opener_of_one_pty_is_refused_naming_the_owner(line, first, second):
    holder = transport(line, first)
    holder.connect()
    try:
        assert lock_holders(line.pty_path)  # the lock is there for others to see
        other = transport(line, second)
        with pytest.raises(LinkDown) as refused:
            other.connect()
        text = str(refused.value)
        assert text.startswith(f'bus offline: {line.pty_path} is in use by this process, pid ')
        assert '\n' not in text and 'stop the other program' in text
        assert not other.connected
    finally:
        holder.close()
    assert not lock_holders(line.pty_path)
    again = transport(line, second)
    again.connect()  # free once the holder closed it
    again.close()


def test_the_holder_keeps_working_while_a_second_opener_is_refused(line):
    holder = transport(line)
    holder.connect()
    try:
        with pytest.raises(LinkDown):
            transport(line).connect()
        assert len(holder.execute(1, ReadCoils(32, 32))) == 32
    finally:
        holder.close()
