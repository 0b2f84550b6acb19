"""
Modbus RTU master on a serial port through pyserial, reading replies by their expected length.

The reply's length follows from its first bytes (:func:`drive_bridge.protocol.rtu.decode_response`,
a pure decoder with a "need more bytes" contract), so the transport asks the port for exactly
the bytes still missing and returns the moment the last one arrives: no inter-character
polling, no end-of-frame guessing (as libmodbus does). This is the default engine for
``protocol: modbus_rtu``; ``serial_engine: pymodbus`` selects pymodbus's serial client instead.
Failures are the typed errors of :mod:`drive_bridge.errors`.
"""

import time
from typing import Callable, Dict, List, Optional

from drive_bridge.devices.base import (
    ReadCoils, ReadRegisters, WriteCoil, WriteCoils, WriteRegister, WriteRegisters)
from drive_bridge.errors import (
    BadFrame, CrcError, DeviceException, NoResponse, TruncatedFrame, WrongAddress)
from drive_bridge.protocol import rtu
from drive_bridge.protocol.rtu import RtuFrame
from drive_bridge.transport.serial_port import PORT_ERRORS, SerialPortTransport


def _request(unit: int, transaction) -> RtuFrame:
    """Return the request frame of one transaction."""
    if isinstance(transaction, ReadRegisters):
        return rtu.read_registers_request(unit, transaction.address, transaction.count)
    if isinstance(transaction, ReadCoils):
        return rtu.read_coils_request(unit, transaction.address, transaction.count)
    if isinstance(transaction, WriteRegister):
        return rtu.write_register_request(unit, transaction.address, transaction.value)
    if isinstance(transaction, WriteCoil):
        return rtu.write_coil_request(unit, transaction.address, transaction.value)
    if isinstance(transaction, WriteRegisters):
        return rtu.write_registers_request(unit, transaction.address, list(transaction.values))
    if isinstance(transaction, WriteCoils):
        return rtu.write_coils_request(unit, transaction.address, list(transaction.values))
    raise TypeError(f'unsupported transaction {transaction!r}')


def _registers(transaction: ReadRegisters, reply: RtuFrame) -> List[int]:
    data = reply.data
    if not data or data[0] != len(data) - 1 or data[0] % 2:
        raise BadFrame(f'register reply with byte count {data[:1].hex()} and '
                       f'{len(data) - 1} data bytes')
    registers = [int.from_bytes(data[i:i + 2], 'big') for i in range(1, len(data), 2)]
    if len(registers) != transaction.count and \
            (transaction.exact or not 0 < len(registers) <= transaction.count):
        raise BadFrame(f'expected {transaction.count} registers, got {len(registers)}')
    return registers


def _coils(transaction: ReadCoils, reply: RtuFrame) -> List[bool]:
    data = reply.data
    if not data or data[0] != len(data) - 1 or data[0] * 8 < transaction.count:
        raise BadFrame(f'expected {transaction.count} coils, got {len(data) - 1} data bytes')
    return [bool(data[1 + i // 8] >> (i % 8) & 1) for i in range(transaction.count)]


_PARSERS: Dict[type, Callable] = {ReadRegisters: _registers, ReadCoils: _coils}
_INVALID_REPLY = {'crc': CrcError, 'wrong_address': WrongAddress}


class RtuSerialTransport(SerialPortTransport):
    """Run single Modbus RTU transactions on a serial port; the bus thread owns it."""

    def execute(self, unit: int, transaction) -> Optional[list]:
        """Run one transaction with device ``unit``; return registers or coils read, or None."""
        self._require_port()
        request = _request(unit, transaction)
        try:
            reply = self._exchange(request)
        except PORT_ERRORS as error:
            raise self._port_failed(error) from error
        if reply.function & 0x80:
            raise DeviceException(reply.data[0])
        parser = _PARSERS.get(type(transaction))
        if parser is not None:
            return parser(transaction, reply)
        if reply.data[:4] != request.data[:4]:  # 05/06 echo, 0F/10 address + quantity
            raise BadFrame(f'write reply {reply.data[:4].hex(" ")} does not match the request '
                           f'{request.data[:4].hex(" ")}')
        return None

    def _exchange(self, request: RtuFrame) -> RtuFrame:
        port = self._port
        port.reset_input_buffer()  # a late reply to an earlier request must not count
        encoded = request.encode()
        port.write(encoded)
        if self.settings.local_echo:
            echo = self._read(len(encoded), time.monotonic() + self.settings.timeout_s)
            if echo != encoded:
                raise BadFrame('the adapter did not echo the request (local_echo is set)')
        return self._receive(request.unit, request.function)

    def _receive(self, unit: int, function: int) -> RtuFrame:
        deadline = time.monotonic() + self.settings.timeout_s
        buffer = b''
        needed = rtu.MIN_RESPONSE_BYTES
        while True:
            buffer += self._read(needed - len(buffer), deadline)
            result = rtu.decode_response(buffer, unit, function)
            if result.frame is not None:
                return result.frame
            if result.error:
                self._drain()
                error_type = _INVALID_REPLY.get(result.error_kind, BadFrame)
                raise error_type(f'invalid reply ({result.error}), {len(buffer)} bytes '
                                 'received')
            if len(buffer) < needed:  # the deadline passed
                if not buffer:
                    raise NoResponse(f'no reply within {self.settings.timeout_s:g} s')
                raise TruncatedFrame(f'truncated reply: {len(buffer)} of {needed} bytes '
                                     f'within {self.settings.timeout_s:g} s')
            needed = result.needed

    def _drain(self) -> None:
        """Drop what is still arriving after a bad reply (one character-gap of silence)."""
        port = self._port
        gap = max(0.005, rtu.frame_gap_s(self.settings.baudrate, self.settings.parity,
                                         self.settings.effective_stopbits))
        port.timeout = gap
        while port.read(256):
            pass
