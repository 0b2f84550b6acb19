"""The transport registry: one factory per protocol in the protocol table, and which it builds."""

import subprocess
import sys

from drive_bridge.transport.ap_ascii import ApAsciiTransport
from drive_bridge.transport.engines import make_transport, TRANSPORTS
from drive_bridge.transport.fc_protocol import FcProtocolTransport
from drive_bridge.transport.link import LinkSettings
from drive_bridge.transport.modbus import ModbusTransport
from drive_bridge.transport.protocols import PROTOCOLS
from drive_bridge.transport.serial_rtu import RtuSerialTransport
import pytest


def test_every_protocol_has_its_transport_factory_and_nothing_else_has_one():
    assert set(TRANSPORTS) == set(PROTOCOLS)


def pymodbus_case(*case):
    """Return a case that builds a pymodbus transport, marked for the pymodbus tier."""
    return pytest.param(*case, marks=pytest.mark.pymodbus)


@pytest.mark.parametrize('protocol, options, expected', [
    ('modbus_rtu', {}, RtuSerialTransport),
    ('modbus_rtu', {'serial_engine': 'native'}, RtuSerialTransport),
    ('ap_ascii', {}, ApAsciiTransport),
    ('fc_protocol', {}, FcProtocolTransport),
    pymodbus_case('modbus_tcp', {}, ModbusTransport),
    ('rtu_over_tcp', {}, RtuSerialTransport),
])
def test_the_transport_of_each_protocol_is_built_without_opening_the_link(
        protocol, options, expected):
    link = LinkSettings(protocol=protocol, port='/nonexistent/ttyNONE', tcp_port=1)
    assert type(make_transport(link, options)) is expected


@pytest.mark.parametrize('module', ['drive_bridge.transport.engines', 'drive_bridge.config.model'])
def test_pymodbus_is_imported_only_by_a_transport_that_uses_it(module):
    """Every node start and CLI command imports the registry; pymodbus costs ~0.1 s of CPU."""
    probe = (f'import sys, {module}; '
             "print(sorted(m for m in sys.modules if m.split('.')[0] == 'pymodbus'))")
    done = subprocess.run([sys.executable, '-c', probe], capture_output=True, text=True,
                          timeout=60, check=True)
    assert done.stdout.strip() == '[]', done.stdout
