"""
A simulated Profibus DP-master gateway with MCD 200 slaves behind it, as a Modbus slave.

Each slave's LVSG process image sits at configurable holding registers: the input bytes
(status and, with the extended module, the operating-parameter answer) and the output bytes
(control and parameter request), two bytes a register in the configured order. Behind the
image is the same :class:`McdModel` as the Modbus Module simulator (MCD 201 or 202). Modelled
from manual ``002_8ae547a04c1e19a0.txt``: Fwd Run 0 -> 1 starts, 1 -> 0 soft-stops (Quick
Stop set: coast), Reset acts on its rising edge, Clear mode quick-stops and inhibits starts
(leaving it with Fwd Run set restarts the motor), and a network failure longer than the GSD
Comms Timeout trips the starter (trip 16). ``modbus_watchdog_s`` makes the gateway enter
Clear mode for a slave whose output image was not written for that long, as gateways can.
"""

from collections import deque
from dataclasses import dataclass, field
import struct
import time
from typing import Deque, Dict, List, Optional

from drive_bridge.protocol import lvsg, rtu
from drive_bridge.protocol.lvsg import Control
from drive_bridge.protocol.rtu import RtuFrame
from drive_bridge.protocol.words import bytes_to_registers, registers_to_bytes
from drive_bridge.sim.mcd_model import (
    McdModel, McdSimConfig, ModuleError, NETWORK_COMMUNICATION_TRIP, RUNNING, STARTING,
    STOPPING, TRIPPED)
from drive_bridge.sim.modbus_server import ModbusSimServer

ILLEGAL_FUNCTION, ILLEGAL_ADDRESS, ILLEGAL_VALUE = 1, 2, 3
SOFTWARE_VERSION = 3


@dataclass
class LvsgSlave:
    """One MCD 200 with its Profibus Module, mapped into the gateway's registers."""

    model: McdModel
    input_register: int
    output_register: int
    extended: bool = True
    byte_order: str = 'big'
    comms_timeout_s: float = 10.0  # GSD Comms Timeout: 0-100 s, default 10 s; 0 = none
    control: Control = field(default_factory=Control)
    clear_mode: bool = False
    network_failed_at: Optional[float] = None
    started_once: bool = False
    last_write_s: Optional[float] = None
    writes: Deque[bytes] = field(default_factory=lambda: deque(maxlen=1000))  # the latest

    @property
    def input_bytes(self) -> int:
        """Return the size of the input image."""
        return lvsg.EXTENDED_INPUT_BYTES if self.extended else lvsg.BASIC_INPUT_BYTES

    @property
    def output_bytes(self) -> int:
        """Return the size of the output image."""
        return lvsg.EXTENDED_OUTPUT_BYTES if self.extended else lvsg.BASIC_OUTPUT_BYTES

    def advance(self, now_s: float) -> None:
        """Advance the starter; a network failure past the Comms Timeout trips it."""
        self.model.advance(now_s)
        failed = self.network_failed_at
        if failed is not None and self.comms_timeout_s > 0 and \
                now_s - failed >= self.comms_timeout_s and self.model.state != TRIPPED:
            self.model.trip(NETWORK_COMMUNICATION_TRIP, now_s)

    def write_output(self, data: bytes, now_s: float) -> None:
        """Take a new output image from the master: act on the edges of the control bits."""
        self.advance(now_s)
        new, old = Control.decode(data), self.control
        self.control = new
        self.last_write_s = now_s
        self.writes.append(bytes(data))
        if new.reset and not old.reset:
            self._command(3, now_s)
        if new.fwd_run and not old.fwd_run and not self.clear_mode:
            self._command(1, now_s)
            self.started_once = True
        elif old.fwd_run and not new.fwd_run:
            self._command(4 if new.quick_stop else 2, now_s)

    def set_clear_mode(self, on: bool, now_s: float) -> None:
        """Global Clear: quick stop and inhibit starts; leaving it with Fwd Run set restarts."""
        self.advance(now_s)
        if on and not self.clear_mode:
            self._command(4, now_s)
        elif not on and self.clear_mode and self.control.fwd_run:
            self.clear_mode = False
            self._command(1, now_s)
        self.clear_mode = on

    def _command(self, value: int, now_s: float) -> None:
        try:
            self.model.write_register(1, value, now_s)
        except ModuleError:
            pass  # the Profibus Module has no way to refuse; the starter just does not act

    def input_image(self, now_s: float) -> bytes:
        """Return the input bytes as the module would send them now."""
        self.advance(now_s)
        model = self.model
        state = model.state
        flc = model.config.motor_flc_a
        answer = self._answer() if self.extended else None
        return lvsg.encode_status(
            ready=state == 1, on=state in (STARTING, RUNNING, STOPPING),
            fault=state == TRIPPED, ramping=state in (STARTING, STOPPING),
            current_raw=lvsg.current_raw_from_pct(100.0 * model.motor_current_a / flc)
            if model.features.has_current else 0, answer=answer)

    def _answer(self) -> tuple:
        model = self.model
        request = self.control.parameter_request
        is_201 = not model.features.has_current
        if request == lvsg.PARAMETER_PRODUCT:
            return request, (lvsg.MCD200_PRODUCT_TYPE << 3) << 8 | SOFTWARE_VERSION, False
        if request == lvsg.PARAMETER_STATE:
            state_byte = min(model.state, 6)
            if model.motor_current_a > model.config.motor_flc_a:
                state_byte |= 1 << lvsg.STATE_BIT_CURRENT_ABOVE_FLC
            if self.started_once:
                state_byte |= 1 << lvsg.STATE_BIT_ROTATION_VALIDATED | \
                    1 << lvsg.STATE_BIT_POSITIVE_ROTATION
            return request, model.trip_code << 8 | state_byte, False
        if request == lvsg.PARAMETER_CURRENT:
            value = lvsg.MCD201_CURRENT_PLACEHOLDER if is_201 else round(model.motor_current_a)
            return request, value, False
        if request == lvsg.PARAMETER_TEMPERATURE:
            value = lvsg.MCD201_TEMPERATURE_PLACEHOLDER if is_201 else \
                round(model.temperature_pct)
            return request, value, False
        return request, 0, True


class LvsgGatewaySim:
    """The gateway's Modbus face: holding registers onto the slaves' process images."""

    def __init__(self, slaves: List[LvsgSlave], modbus_watchdog_s: float = 0.0):
        self.slaves = slaves
        self.modbus_watchdog_s = modbus_watchdog_s
        self.model = slaves[0].model if slaves else None  # the console's view of slave 1

    def handle(self, frame: RtuFrame, now_s: float) -> Optional[RtuFrame]:
        """Answer a Modbus request on the process images."""
        self._watchdog(now_s)
        try:
            if frame.function == rtu.READ_HOLDING_REGISTERS and len(frame.data) == 4:
                address, count = rtu.parse_address_count(frame.data)
                values = self._read(address, count, now_s)
                return rtu.registers_response(frame.unit, frame.function, values)
            if frame.function == rtu.WRITE_SINGLE_REGISTER and len(frame.data) == 4:
                address, value = rtu.parse_address_count(frame.data)
                self._write(address, [value], now_s)
                return RtuFrame(frame.unit, frame.function, frame.data)
            if frame.function == rtu.WRITE_MULTIPLE_REGISTERS and len(frame.data) >= 5:
                address, count = rtu.parse_address_count(frame.data)
                if frame.data[4] != 2 * count or len(frame.data) != 5 + 2 * count:
                    raise _Exception(ILLEGAL_VALUE)
                self._write(address, list(struct.unpack(f'>{count}H', frame.data[5:])),
                            now_s)
                return RtuFrame(frame.unit, frame.function, frame.data[:4])
            raise _Exception(ILLEGAL_FUNCTION)
        except _Exception as error:
            return rtu.exception_response(frame.unit, frame.function, error.code)

    def _area(self, address: int, count: int):
        """Return (slave, 'input' or 'output', register offset) of a register range."""
        for slave in self.slaves:
            for start, size, kind in ((slave.input_register, slave.input_bytes, 'input'),
                                      (slave.output_register, slave.output_bytes, 'output')):
                offset = address - start
                if 0 <= offset and count >= 1 and offset + count <= (size + 1) // 2:
                    return slave, kind, offset
        raise _Exception(ILLEGAL_ADDRESS)

    def _read(self, address: int, count: int, now_s: float) -> List[int]:
        slave, kind, offset = self._area(address, count)
        if kind == 'input':
            data = slave.input_image(now_s)
        else:
            data = slave.control.encode(slave.extended)
        return bytes_to_registers(data, slave.byte_order)[offset:offset + count]

    def _write(self, address: int, values: List[int], now_s: float) -> None:
        """Write output registers; a part of the image keeps the other registers' bytes."""
        slave, kind, offset = self._area(address, len(values))
        if kind != 'output':
            raise _Exception(ILLEGAL_ADDRESS)
        registers = bytes_to_registers(slave.control.encode(slave.extended), slave.byte_order)
        registers[offset:offset + len(values)] = values
        slave.write_output(registers_to_bytes(registers, slave.output_bytes, slave.byte_order),
                           now_s)
        if slave.clear_mode and self.modbus_watchdog_s:
            # The Modbus side is back: the DP master leaves Clear with the image just
            # written, so only a Fwd Run in that image restarts the starter.
            slave.set_clear_mode(False, now_s)

    def _watchdog(self, now_s: float) -> None:
        if not self.modbus_watchdog_s:
            return
        for slave in self.slaves:
            if slave.last_write_s is not None and not slave.clear_mode and \
                    now_s - slave.last_write_s > self.modbus_watchdog_s:
                slave.set_clear_mode(True, now_s)


class _Exception(Exception):
    def __init__(self, code: int):
        super().__init__(code)
        self.code = code


def make_lvsg_gateway(slaves: Dict[int, tuple], unit: int = 1, modbus_watchdog_s: float = 0.0,
                      **settings) -> ModbusSimServer:
    """
    Return a simulated gateway at Modbus ``unit`` with MCD 200 slaves behind it.

    ``slaves`` maps an input register to (model, output register, module), e.g.
    ``{0: ('mcd202', 100, 'extended')}``; ``settings`` go to every McdSimConfig.
    """
    now = time.monotonic()
    images = [LvsgSlave(McdModel(McdSimConfig(model=model, **settings), now), in_reg, out_reg,
                        module == 'extended')
              for in_reg, (model, out_reg, module) in slaves.items()]
    return ModbusSimServer({unit: LvsgGatewaySim(images, modbus_watchdog_s)})
