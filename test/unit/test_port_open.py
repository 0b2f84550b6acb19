"""Opening a serial port: a refusal names the settings refused, on fake ports (no device)."""

import errno
import termios

from drive_bridge.errors import LinkDown
from drive_bridge.transport.fc_protocol import FcProtocolTransport
from drive_bridge.transport.link import LinkSettings, port_framing, PortFraming
from drive_bridge.transport.serial_rtu import RtuSerialTransport
import pytest
import serial

EINVAL = termios.error(errno.EINVAL, 'Invalid argument')  # as pyserial lets it through


def refusing(*args, **kwargs):
    """Open nothing: the driver refuses the settings, as tcsetattr does."""
    raise EINVAL


def refusing_through_pyserial(*args, **kwargs):
    """Refuse as pyserial words it when tcgetattr fails (the errno only in the context)."""
    try:
        raise EINVAL
    except termios.error as error:
        raise serial.SerialException(f'Could not configure port: {error}')


@pytest.fixture
def port(tmp_path):
    """Return a path that exists and is no pty (a real adapter's device, as far as we care)."""
    path = tmp_path / 'ttyUSB0'
    path.write_text('')
    return str(path)


def refused(port: str, baudrate: int, parity: str, stopbits: int) -> str:
    return (f'bus offline: cannot open {port}: the port refused baudrate {baudrate}, parity '
            f'{parity}, stopbits {stopbits} (EINVAL): its adapter or driver does not take these '
            'settings; check baudrate, parity and stopbits')


@pytest.mark.parametrize('open_port', [refusing, refusing_through_pyserial])
def test_a_port_that_refuses_its_settings_names_them_in_one_line(port, open_port):
    transport = RtuSerialTransport(LinkSettings(port=port, baudrate=19200, parity='E'),
                                   open_port=open_port)
    with pytest.raises(LinkDown) as raised:
        transport.connect()
    assert str(raised.value) == refused(port, 19200, 'E', 1)
    assert not transport.connected


def test_the_fc_protocol_names_the_settings_refused_too(port):
    transport = FcProtocolTransport(LinkSettings(protocol='fc_protocol', port=port,
                                                 parity='O', stopbits=2), open_port=refusing)
    with pytest.raises(LinkDown) as raised:
        transport.connect()
    assert str(raised.value) == refused(port, 9600, 'O', 2)


def test_a_port_that_is_no_pty_is_opened_with_the_link_s_framing(port):
    for parity, stopbits in (('E', 0), ('O', 2), ('N', 0)):
        settings = LinkSettings(port=port, parity=parity, stopbits=stopbits)
        assert port_framing(settings) == PortFraming(parity, settings.effective_stopbits)
    url = LinkSettings(port='socket://127.0.0.1:5020', parity='E')
    assert port_framing(url) == PortFraming('E', 1)
