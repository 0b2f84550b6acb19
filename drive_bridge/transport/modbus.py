"""
Modbus RTU (serial), Modbus TCP and RTU over TCP through pymodbus, 3.6.9 to 3.16.

One adapter hides the API differences: the unit keyword (``slave=`` before 3.10,
``device_id=`` after), the framer enum (``Framer`` / ``FramerType``), whether errors are
returned or raised, and the write echo's field names. pymodbus's own retries are off: the
bus owns the retry policy. Failures are raised as the typed errors of
:mod:`drive_bridge.errors`, classified by kind for the statistics.
"""

import inspect
import logging
import time
from typing import List, Optional

from drive_bridge.errors import (
    BadFrame, DeviceException, LineBabble, LinkDown, NoResponse, TransportError)
from drive_bridge.protocol.requests import (
    ReadCoils, ReadRegisters, WriteCoil, WriteCoils, WriteRegister, WriteRegisters)
from drive_bridge.transport.base import Transport
from drive_bridge.transport.link import (  # noqa: F401 - LinkSettings, wire_time_s re-exported
    LinkSettings, port_framing, port_missing, PortFraming, wire_time_s)
from drive_bridge.transport.modbus_replies import settle, TappedSerialClient
from drive_bridge.transport.port_owner import in_use_text, lock_holders
from drive_bridge.transport.serial_port import note_framing, open_serial, PORT_ERRORS
import pymodbus
from pymodbus.client import ModbusSerialClient, ModbusTcpClient
from pymodbus.exceptions import ConnectionException, ModbusException, ModbusIOException

try:  # pymodbus >= 3.7
    from pymodbus import FramerType as _Framer
except ImportError:  # pymodbus 3.6
    from pymodbus.framer import Framer as _Framer

PYMODBUS_VERSION = pymodbus.__version__
# pymodbus logs every timeout at ERROR; the bus counts and reports failures itself.
logging.getLogger('pymodbus').setLevel(logging.CRITICAL)
_UNIT_KEYWORD = (
    'device_id'
    if 'device_id' in inspect.signature(ModbusSerialClient.read_holding_registers).parameters
    else 'slave')
_HAS_TRACE_PACKET = 'trace_packet' in inspect.signature(ModbusSerialClient.__init__).parameters
_GATEWAY_EXCEPTIONS = {0x0A: 'gateway path unavailable', 0x0B: 'gateway target did not respond'}

RECEIVE_POLL_INTERVAL_S = 0.0005
BABBLE_WINDOWS = 4  # pauses after a bad reply, each one with bytes in it: babble
BABBLE_WINDOW_S = 0.02  # longer than a USB adapter's ~16 ms batches


class ModbusTransport(Transport):
    """Run single Modbus transactions on one bus; not thread-safe (the bus thread owns it)."""

    def __init__(self, settings: LinkSettings):
        super().__init__(settings)
        self._client = None
        self._received = bytearray()
        self._framing_noted = False  # the note of a pty's framing is logged once

    # -- connection ---------------------------------------------------------------------
    @property
    def connected(self) -> bool:
        """Return whether the port or connection is open."""
        return self._client is not None

    def connect(self) -> None:
        """Open the port or connection; raise LinkDown with the reason in words."""
        self.close()
        settings = self.settings
        if port_missing(settings):
            raise LinkDown(f'bus offline: {settings.port} not found')
        framing = port_framing(settings) if settings.is_serial else None
        client = self._make_client(framing)
        try:
            ok = client.connect()
        except (*PORT_ERRORS, ModbusException) as error:  # pymodbus 3.6 lets some through
            client.close()
            if framing is not None:
                self._why_not_open(framing)
            raise LinkDown(f'bus offline: cannot open {settings.describe()}: {error}') from error
        if not ok:
            client.close()
            if settings.is_serial and lock_holders(settings.port):  # pymodbus opens exclusively
                raise LinkDown(f'bus offline: {in_use_text(settings.port)}')
            if framing is not None:
                self._why_not_open(framing)
            raise LinkDown(f'bus offline: cannot open {settings.describe()}')
        if framing is not None:
            self._framing_noted = note_framing(framing, self._framing_noted)
        if hasattr(client, '_recv_interval'):
            # pymodbus >= 3.10 polls the port every 4 characters and ends a read when a poll
            # sees no new byte, which adds up to 8 character times to every reply. Its
            # framer joins partial reads, so a short poll interval is safe and near exact.
            client._recv_interval = RECEIVE_POLL_INTERVAL_S
        self._client = client

    def _why_not_open(self, framing: PortFraming) -> None:
        """
        Raise LinkDown saying why the serial port did not open (returns if it opens now).

        pymodbus only logs why (and returns False): the port is opened once more, the same
        way, to learn the reason, and closed again.
        """
        open_serial(self.settings, framing).close()

    def _make_client(self, framing: Optional[PortFraming]):
        settings = self.settings
        common = {'timeout': settings.timeout_s, 'retries': 0}
        serial_extra = {}
        if _HAS_TRACE_PACKET:
            common['trace_packet'] = self._trace_packet
        else:  # pymodbus 3.6: no retry on empty, no strict character timing
            common.update(retry_on_empty=False, reconnect_delay=0)
            serial_extra['strict'] = False
        if framing is not None:
            return TappedSerialClient(
                port=settings.port, framer=_Framer.RTU, baudrate=settings.baudrate,
                bytesize=8, parity=framing.parity, stopbits=framing.stopbits,
                handle_local_echo=settings.local_echo, **serial_extra, **common)
        framer = _Framer.SOCKET if settings.protocol == 'modbus_tcp' else _Framer.RTU
        return ModbusTcpClient(host=settings.host, port=settings.tcp_port, framer=framer,
                               **common)

    def close(self) -> None:
        """Close the port or connection (idempotent)."""
        client, self._client = self._client, None
        if client is not None:
            try:
                client.close()
            except (OSError, ModbusException):
                pass

    def _trace_packet(self, sending: bool, data: bytes) -> bytes:
        if not sending:  # pymodbus passes everything received so far in this transaction
            self._received[:] = data
        return data

    # -- transactions -------------------------------------------------------------------
    def execute(self, unit: int, transaction) -> Optional[list]:
        """Run one transaction with device ``unit``; return registers or coils read, or None."""
        if self._client is None:
            raise LinkDown('bus offline: not connected')
        handler = self._HANDLERS.get(type(transaction))
        if handler is None:
            raise TypeError(f'unsupported transaction {transaction!r}')
        self._received.clear()
        self.last_recovered = {}
        client, deadline = self._client, time.monotonic() + self.settings.timeout_s
        if not isinstance(client, TappedSerialClient):  # not a serial line
            return self._run(handler, unit, transaction)
        try:
            outcome, failure = self._run(handler, unit, transaction), None
        except LinkDown:
            raise
        except TransportError as error:
            outcome, failure = None, error
        return settle(client, unit, transaction, deadline, outcome, failure, self.last_recovered)

    def _run(self, handler, unit: int, transaction) -> Optional[list]:
        """Run the transaction through pymodbus; raise its failure as a typed error."""
        try:
            return handler(self, {_UNIT_KEYWORD: unit}, transaction)
        except ConnectionException as error:
            self.close()
            raise LinkDown(f'bus offline: {self.settings.describe()}: {error}') from error
        except ModbusIOException as error:
            raise self._classify_io_error(str(error)) from error
        except (OSError, ValueError) as error:
            self.close()
            raise LinkDown(f'bus offline: {self.settings.describe()}: {error}') from error

    def _read_registers(self, keyword: dict, transaction: ReadRegisters) -> List[int]:
        response = self._client.read_holding_registers(
            transaction.address, count=transaction.count, **keyword)
        self._check(response)
        return transaction.check_count(list(response.registers))

    def _read_coils(self, keyword: dict, transaction: ReadCoils) -> List[bool]:
        response = self._client.read_coils(transaction.address, count=transaction.count,
                                           **keyword)
        self._check(response)
        coils = list(response.bits)
        if len(coils) < transaction.count:
            raise BadFrame(f'expected {transaction.count} coils, got {len(coils)}')
        return coils[:transaction.count]

    def _write_register(self, keyword: dict, transaction: WriteRegister) -> None:
        response = self._client.write_register(transaction.address, transaction.value,
                                               **keyword)
        self._check(response)
        self._check_echo(response, transaction.address, transaction.value)

    def _write_coil(self, keyword: dict, transaction: WriteCoil) -> None:
        response = self._client.write_coil(transaction.address, transaction.value, **keyword)
        self._check(response)
        self._check_echo(response, transaction.address, transaction.value)

    def _write_registers(self, keyword: dict, transaction: WriteRegisters) -> None:
        response = self._client.write_registers(transaction.address,
                                                list(transaction.values), **keyword)
        self._check(response)
        self._check_count(response, transaction.address, len(transaction.values))

    def _write_coils(self, keyword: dict, transaction: WriteCoils) -> None:
        response = self._client.write_coils(transaction.address, list(transaction.values),
                                            **keyword)
        self._check(response)
        self._check_count(response, transaction.address, len(transaction.values))

    _HANDLERS = {
        ReadRegisters: _read_registers, ReadCoils: _read_coils,
        WriteRegister: _write_register, WriteCoil: _write_coil,
        WriteRegisters: _write_registers, WriteCoils: _write_coils,
    }

    def _check(self, response) -> None:
        if isinstance(response, ModbusIOException):  # pymodbus 3.6 returns these
            raise self._classify_io_error(str(response))
        if not response.isError():
            return
        code = getattr(response, 'exception_code', None)
        if code is None:
            raise self._classify_io_error(str(response))
        if code in _GATEWAY_EXCEPTIONS and self.settings.protocol == 'modbus_tcp':
            # A Modbus TCP gateway's own answer: its serial device did not answer. On a
            # serial line (or through a transparent gateway) the device itself answers, and
            # codes 10 and 11 are its own (the MCD module's 10: local communication error).
            raise NoResponse(f'no reply: {_GATEWAY_EXCEPTIONS[code]} '
                             f'(Modbus exception {code:02X}h)')
        raise DeviceException(code)

    @staticmethod
    def _check_echo(response, address: int, expected) -> None:
        """Check a function 05/06 echo: same address and value as the request."""
        echoed = getattr(response, 'value', None)
        if echoed is None:
            echoed = (getattr(response, 'registers', None) or getattr(response, 'bits', None)
                      or [None])[0]
        if isinstance(expected, bool):
            echoed = bool(echoed)
        if response.address != address or echoed != expected:
            raise BadFrame(f'write echo {response.address}={echoed} does not match '
                           f'{address}={expected}')

    @staticmethod
    def _check_count(response, address: int, count: int) -> None:
        """Check a function 0F/10 reply: same start address and quantity as the request."""
        echoed = getattr(response, 'count', None)
        if response.address != address or (echoed is not None and echoed != count):
            raise BadFrame(f'write reply {response.address}/{echoed} does not match '
                           f'{address}/{count}')

    def _line_keeps_talking(self) -> bool:
        """
        Return whether bytes keep arriving on a serial line after a bad reply (babble).

        A device answers once and falls silent; bytes in each of a few pauses after the
        transaction ended mean something else is talking. What arrives is dropped.
        """
        port = self._open_serial_port()
        if port is None:
            return False
        try:
            for _ in range(BABBLE_WINDOWS):
                port.reset_input_buffer()
                time.sleep(BABBLE_WINDOW_S)
                if not port.in_waiting:
                    return False
            port.reset_input_buffer()
        except PORT_ERRORS:
            return False
        return True

    def _open_serial_port(self):
        """Return the client's serial port, reopened if pymodbus closed it (None: TCP)."""
        if not self.settings.is_serial:
            return None
        port = getattr(self._client, 'socket', None)
        if port is None:  # pymodbus 3.6 closes the port after a reply it cannot decode
            try:
                self._client.connect()
            except PORT_ERRORS:
                return None
            port = getattr(self._client, 'socket', None)
        return port

    def _classify_io_error(self, text: str):
        if port_missing(self.settings):
            self.close()
            return LinkDown(f'bus offline: {self.settings.port} not found')
        timeout = f'{self.settings.timeout_s:g} s'
        if self._received or 'decode' in text.lower():
            if self._line_keeps_talking():
                return LineBabble(f'bus offline: {self.settings.describe()}: the line keeps '
                                  'talking past a bad reply: another master or a faulty '
                                  'device is sending')
            return BadFrame(f'invalid reply (CRC error, garbage or wrong address), '
                            f'{len(self._received)} bytes received')
        return NoResponse(f'no reply within {timeout}')
