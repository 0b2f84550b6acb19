"""
Modbus TCP through pymodbus, 3.6.9 to 3.16.

Modbus TCP replies carry the request's transaction id, which pymodbus matches: a late reply
is dropped by its id on the TCP hop, so this transport needs none of the line discipline
of the serial protocols (:mod:`drive_bridge.transport.exchange`). Modbus RTU, on a serial
port or over TCP (``rtu_over_tcp``), runs on the native engine (:mod:`.serial_rtu`):
pymodbus's serial client takes the first frame it reads (3.16 drops what follows, 3.6.9
reads the first frame's length), so it can keep neither "one frame per reply window" nor
the end-of-frame silence, and it was removed (docs/reliability.md, "Late replies").

One adapter hides the API differences: the unit keyword (``slave=`` before 3.10,
``device_id=`` after), whether errors are returned or raised, and the write echo's field
names. pymodbus's own retries are off: the bus owns the retry policy. Failures are raised
as the typed errors of :mod:`drive_bridge.errors`, classified by kind for the statistics.
"""

import inspect
import logging
from typing import List, Optional

from drive_bridge.errors import BadFrame, DeviceException, LinkDown, NoResponse
from drive_bridge.protocol.requests import (
    ReadCoils, ReadRegisters, WriteCoil, WriteCoils, WriteRegister, WriteRegisters)
from drive_bridge.transport.base import trace_interface, Transport
from drive_bridge.transport.link import LinkSettings  # noqa: F401 - re-exported
from drive_bridge.transport.packet_trace import PacketTracer
from drive_bridge.transport.trace_writer import QueuedTrace
from drive_bridge.transport.wire_trace import TraceSettings, WireTrace
import pymodbus
from pymodbus.client import ModbusTcpClient
from pymodbus.exceptions import ConnectionException, ModbusException, ModbusIOException

PYMODBUS_VERSION = pymodbus.__version__
# pymodbus logs every timeout at ERROR; the bus counts and reports failures itself.
logging.getLogger('pymodbus').setLevel(logging.CRITICAL)
_UNIT_KEYWORD = (
    'device_id'
    if 'device_id' in inspect.signature(ModbusTcpClient.read_holding_registers).parameters
    else 'slave')
_HAS_TRACE_PACKET = 'trace_packet' in inspect.signature(ModbusTcpClient.__init__).parameters
_GATEWAY_EXCEPTIONS = {0x0A: 'gateway path unavailable', 0x0B: 'gateway target did not respond'}


class ModbusTransport(Transport):
    """Run single Modbus TCP transactions; not thread-safe (the bus thread owns it)."""

    def __init__(self, settings: LinkSettings):
        super().__init__(settings)
        self._client = None
        self._tracer: Optional[PacketTracer] = None  # the wire trace's, when one is on

    # -- connection ---------------------------------------------------------------------
    @property
    def connected(self) -> bool:
        """Return whether the port or connection is open."""
        return self._client is not None

    def connect(self) -> None:
        """Open the connection; raise LinkDown with the reason in words."""
        self.close()
        settings = self.settings
        common = {'timeout': settings.timeout_s, 'retries': 0}
        if not _HAS_TRACE_PACKET:  # pymodbus 3.6: no retry on empty, no reconnect delay
            common.update(retry_on_empty=False, reconnect_delay=0)
        elif self._tracer is not None:
            common.update(trace_packet=self._tracer.packet)
        client = ModbusTcpClient(host=settings.host, port=settings.tcp_port, **common)
        if self._tracer is not None and not _HAS_TRACE_PACKET:
            self._tracer.wrap(client)
        try:
            ok = client.connect()
        except (OSError, ModbusException) as error:  # pymodbus 3.6 lets some through
            client.close()
            raise LinkDown(f'bus offline: cannot open {settings.describe()}: {error}') from error
        if not ok:
            client.close()
            raise LinkDown(f'bus offline: cannot open {settings.describe()}')
        self._client = client

    def close(self) -> None:
        """Close the port or connection (idempotent); the trace's queue is written first."""
        if self._tracer is not None:
            self._tracer.trace.drain()
        client, self._client = self._client, None
        if client is not None:
            try:
                client.close()
            except (OSError, ModbusException):
                pass

    def start_trace(self, trace: TraceSettings) -> None:
        """Trace the ADUs pymodbus sends and receives (:mod:`.packet_trace`)."""
        self._tracer = PacketTracer(QueuedTrace(WireTrace(
            trace, trace_interface(self.settings), 'modbus_tcp')))

    # -- transactions -------------------------------------------------------------------
    def execute(self, unit: int, transaction) -> Optional[list]:
        """Run one transaction with device ``unit``; return registers or coils read, or None."""
        if self._client is None:
            raise LinkDown('bus offline: not connected')
        handler = self._HANDLERS.get(type(transaction))
        if handler is None:
            raise TypeError(f'unsupported transaction {transaction!r}')
        self.last_recovered = {}
        if self._tracer is None:
            return self._run(handler, unit, transaction)
        try:
            result = self._run(handler, unit, transaction)
        except Exception as error:
            self._tracer.end(unit, error)
            raise
        self._tracer.end(unit, None)
        return result

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
        if code in _GATEWAY_EXCEPTIONS:
            # A Modbus TCP gateway's own answer: its serial device did not answer. On a
            # serial line (or through a transparent gateway: the native engine) the device
            # itself answers, and codes 10 and 11 are its own (the MCD module's 10: local
            # communication error).
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

    def _classify_io_error(self, text: str):
        if 'decode' in text.lower():
            return BadFrame(f'invalid reply ({text})')
        return NoResponse(f'no reply within {self.settings.timeout_s:g} s')
