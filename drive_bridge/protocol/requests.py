"""
The request vocabulary: every transaction a profile can ask the bus for, and its encodings.

Pure. A request knows its own encoding for each wire format that carries it, as pymodbus's
PDUs do: the Modbus requests build their RTU frame (also used for Modbus TCP and RTU over TCP
by the native engines) and parse the reply; the AP ASCII requests name their code. The
pymodbus adapter maps them onto its client calls by function code. Every request says whether
it ``writes`` (changes anything in the device): the bus refuses a writing request to a
monitor-only device whatever asked for it.
"""

from dataclasses import dataclass
from typing import ClassVar, List, Optional, Tuple

from drive_bridge.errors import BadFrame
from drive_bridge.protocol import rtu
from drive_bridge.protocol.rtu import RtuFrame


class Request:
    """Base of every request; ``writes``: it may change the device (a command, a set-up)."""

    writes: ClassVar[bool] = False

    def describe(self) -> str:
        """Return the request in words for messages and logs."""
        return repr(self)


class ModbusRequest(Request):
    """A Modbus request: encodes itself as an RTU frame and parses the reply."""

    function: ClassVar[int] = 0

    def frame(self, unit: int) -> RtuFrame:
        """Return the request frame for device ``unit`` (without CRC)."""
        raise NotImplementedError

    def reply_length(self) -> int:
        """Return the length of the normal (not exception) RTU reply, CRC included."""
        return 8  # writes: unit, function, address and value or quantity, CRC

    def parse(self, request: RtuFrame, reply: RtuFrame) -> Optional[list]:
        """Return what the reply carries (None for writes); raise BadFrame if it does not fit."""
        if reply.data[:4] != request.data[:4]:  # 05/06 echo, 0F/10 address + quantity
            raise BadFrame(f'write reply {reply.data[:4].hex(" ")} does not match the request '
                           f'{request.data[:4].hex(" ")}')
        return None


@dataclass(frozen=True)
class ReadRegisters(ModbusRequest):
    """
    Read ``count`` holding registers (function 03) from frame address ``address``.

    ``exact``: the reply must carry ``count`` registers; False for text parameters, which
    the FC series answers with fewer registers when the text is shorter (manual 004, 5.4.4).
    """

    address: int
    count: int
    exact: bool = True
    function: ClassVar[int] = rtu.READ_HOLDING_REGISTERS

    def frame(self, unit: int) -> RtuFrame:
        """Return the function 03 request."""
        return rtu.read_registers_request(unit, self.address, self.count)

    def reply_length(self) -> int:
        """Return the reply's length: unit, function, byte count, registers, CRC."""
        return 5 + 2 * self.count

    def parse(self, request: RtuFrame, reply: RtuFrame) -> List[int]:
        """Return the registers read."""
        data = reply.data
        if not data or data[0] != len(data) - 1 or data[0] % 2:
            raise BadFrame(f'register reply with byte count {data[:1].hex()} and '
                           f'{len(data) - 1} data bytes')
        registers = [int.from_bytes(data[i:i + 2], 'big') for i in range(1, len(data), 2)]
        return self.check_count(registers)

    def check_count(self, registers: List[int]) -> List[int]:
        """Return ``registers`` if their number fits the request, else raise BadFrame."""
        if len(registers) != self.count and \
                (self.exact or not 0 < len(registers) <= self.count):
            raise BadFrame(f'expected {self.count} registers, got {len(registers)}')
        return registers


@dataclass(frozen=True)
class ReadCoils(ModbusRequest):
    """Read ``count`` coils (function 01) from coil address ``address`` (coil number - 1)."""

    address: int
    count: int
    function: ClassVar[int] = rtu.READ_COILS

    def frame(self, unit: int) -> RtuFrame:
        """Return the function 01 request."""
        return rtu.read_coils_request(unit, self.address, self.count)

    def reply_length(self) -> int:
        """Return the reply's length: unit, function, byte count, coil bytes, CRC."""
        return 5 + (self.count + 7) // 8

    def parse(self, request: RtuFrame, reply: RtuFrame) -> List[bool]:
        """Return the coils read."""
        data = reply.data
        if not data or data[0] != len(data) - 1 or data[0] * 8 < self.count:
            raise BadFrame(f'expected {self.count} coils, got {len(data) - 1} data bytes')
        return [bool(data[1 + i // 8] >> (i % 8) & 1) for i in range(self.count)]


@dataclass(frozen=True)
class WriteRegister(ModbusRequest):
    """Write one holding register (function 06) at frame address ``address``."""

    address: int
    value: int
    writes: ClassVar[bool] = True
    function: ClassVar[int] = rtu.WRITE_SINGLE_REGISTER

    def frame(self, unit: int) -> RtuFrame:
        """Return the function 06 request."""
        return rtu.write_register_request(unit, self.address, self.value)


@dataclass(frozen=True)
class WriteRegisters(ModbusRequest):
    """Write several holding registers (function 10) from frame address ``address``."""

    address: int
    values: Tuple[int, ...]
    writes: ClassVar[bool] = True
    function: ClassVar[int] = rtu.WRITE_MULTIPLE_REGISTERS

    def frame(self, unit: int) -> RtuFrame:
        """Return the function 10 request."""
        return rtu.write_registers_request(unit, self.address, list(self.values))


@dataclass(frozen=True)
class WriteCoils(ModbusRequest):
    """Write coils (function 0F) from coil address ``address``; ``values`` one bool a coil."""

    address: int
    values: Tuple[bool, ...]
    writes: ClassVar[bool] = True
    function: ClassVar[int] = rtu.WRITE_MULTIPLE_COILS

    def frame(self, unit: int) -> RtuFrame:
        """Return the function 0F request."""
        return rtu.write_coils_request(unit, self.address, list(self.values))


@dataclass(frozen=True)
class WriteCoil(ModbusRequest):
    """Write one coil (function 05) at coil address ``address``."""

    address: int
    value: bool
    writes: ClassVar[bool] = True
    function: ClassVar[int] = rtu.WRITE_SINGLE_COIL

    def frame(self, unit: int) -> RtuFrame:
        """Return the function 05 request."""
        return rtu.write_coil_request(unit, self.address, self.value)


@dataclass(frozen=True)
class AsciiCommand(Request):
    """AP ASCII: send command ``code`` (e.g. ``B10``); acknowledged with ACK."""

    code: str
    writes: ClassVar[bool] = True


@dataclass(frozen=True)
class AsciiRequest(Request):
    """AP ASCII: send request ``code`` (e.g. ``C22``); the reply is 'status' or 'data'."""

    code: str
    reply: str = 'status'


MODBUS_REQUESTS = (ReadRegisters, ReadCoils, WriteRegister, WriteRegisters, WriteCoils,
                   WriteCoil)
AP_ASCII_REQUESTS = (AsciiCommand, AsciiRequest)
