"""The MCD Modbus Module as a simulated slave: functions 03 and 06 onto :class:`McdModel`."""

import time
from typing import Any, Dict, Optional

from drive_bridge.protocol import rtu
from drive_bridge.protocol.rtu import RtuFrame
from drive_bridge.sim.mcd_model import McdModel, McdSimConfig, ModuleError
from drive_bridge.sim.modbus_server import ModbusSimServer

ILLEGAL_FUNCTION = 1  # manual section 9: function other than 03 or 06


class McdSimDevice:
    """Answers Modbus requests like an MCD Modbus Module (or Remote Operator)."""

    def __init__(self, model: McdModel):
        self.model = model

    def handle(self, frame: RtuFrame, now_s: float) -> Optional[RtuFrame]:
        """Answer one request; module errors become exception replies with their code."""
        if frame.unit == 0:
            return None  # "Modbus broadcast functions are not supported" (section 8)
        try:
            if frame.function == rtu.READ_HOLDING_REGISTERS and len(frame.data) == 4:
                address, count = rtu.parse_address_count(frame.data)
                values = self.model.read_registers(address, count, now_s)
                return rtu.registers_response(frame.unit, frame.function, values)
            if frame.function == rtu.WRITE_SINGLE_REGISTER and len(frame.data) == 4:
                address, value = rtu.parse_address_count(frame.data)
                self.model.write_register(address, value, now_s)
                return RtuFrame(frame.unit, frame.function, frame.data)  # echo = acknowledge
            raise ModuleError(ILLEGAL_FUNCTION)
        except ModuleError as error:
            return rtu.exception_response(frame.unit, frame.function, error.code)


def make_mcd_device(model: str, now_s: float, **settings: Any) -> McdSimDevice:
    """Return a simulated MCD starter of ``model`` (settings go to its :class:`McdSimConfig`)."""
    return McdSimDevice(McdModel(McdSimConfig(model=model, **settings), now_s))


def make_mcd_server(models: Dict[int, str], wire=None, **settings) -> ModbusSimServer:
    """
    Return a simulated bus with one MCD per address: ``{20: 'mcd500', 21: 'mcd202'}``.

    ``settings`` go to every device's :class:`McdSimConfig` (e.g. ``start_time_s=0.5``).
    """
    now = time.monotonic()
    devices = {unit: make_mcd_device(model, now, **settings) for unit, model in models.items()}
    return ModbusSimServer(devices, wire=wire)
