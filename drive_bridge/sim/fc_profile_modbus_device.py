"""
Simulated Modbus faces of FC-profile drives, onto :class:`FcProfileModel`.

FC 51 built-in interface (manual 004 section 5.2.8): coils 1-16 control word, 17-32
reference, 33-48 status word, 49-64 main actual value, 65 EEPROM store; holding registers
7 last error, 9 index, 50000 CTW, 50010 REF, 50200 STW, 50210 MAV (frame address = number -
1), parameter PNU at 10 * PNU - 1. Functions 01, 03, 05, 06, 0F, 10; others exception 01;
a parameter error is exception 04 with the detail in register 7.

VLT 5000/6000 option card (manual 003 "Memory Mapping"): the same coils; registers 1 IND,
2/3 Modbus and drive comms timeouts (10 ms units), parameter N at 10 * N - 1; a parameter
error is answered with the drive's own error code as the exception code (0, 1, 2, 5, 17 ...),
bad addresses with 64, bad lengths with 66, other functions with 67.
"""

import struct
from typing import Any, Callable, Dict, List, Optional

from drive_bridge.protocol import rtu
from drive_bridge.protocol.rtu import RtuFrame
from drive_bridge.protocol.words import coils_to_words, words_to_coils
from drive_bridge.sim.fc_profile_model import FcProfileModel, FcProfileSimConfig
from drive_bridge.sim.fc_profile_parameter_store import ParameterError

ILLEGAL_FUNCTION, ILLEGAL_ADDRESS, ILLEGAL_VALUE, DEVICE_FAILURE = 1, 2, 3, 4
# The option card's own codes for the same faults ("VLT 6000 Errors").
OPTION_CARD_CODES = {ILLEGAL_FUNCTION: 67, ILLEGAL_ADDRESS: 64, ILLEGAL_VALUE: 66}
COIL_COUNT = 65
REGISTER_LAST_ERROR, REGISTER_INDEX = 6, 8
REGISTER_CTW, REGISTER_REF, REGISTER_STW, REGISTER_MAV = 49999, 50009, 50199, 50209


class SlaveError(Exception):
    """Answer with Modbus exception ``code``."""

    def __init__(self, code: int):
        super().__init__(f'exception {code}')
        self.code = code


class FcProfileModbusDevice:
    """Answers Modbus requests like an FC 51's built-in RS-485 interface."""

    def __init__(self, model: FcProfileModel):
        self.model = model
        self.option_card = model.family == 'vlt'
        self._handlers: Dict[int, Callable[[bytes, float], bytes]] = {
            rtu.READ_COILS: self._read_coils,
            rtu.READ_HOLDING_REGISTERS: self._read_registers,
            rtu.WRITE_SINGLE_COIL: self._write_coil,
            rtu.WRITE_SINGLE_REGISTER: self._write_register,
            rtu.WRITE_MULTIPLE_COILS: self._write_coils,
            rtu.WRITE_MULTIPLE_REGISTERS: self._write_registers,
        }

    def handle(self, frame: RtuFrame, now_s: float) -> Optional[RtuFrame]:
        """Answer one request; errors become exception replies (04 sets register 7)."""
        if frame.unit == 0:
            return None  # broadcast: no reply (the model does not act on broadcasts)
        handler = self._handlers.get(frame.function)
        try:
            if handler is None or len(frame.data) < 4:
                raise SlaveError(ILLEGAL_FUNCTION if handler is None else ILLEGAL_VALUE)
            return RtuFrame(frame.unit, frame.function, handler(frame.data, now_s))
        except ParameterError as error:
            if self.option_card:
                return rtu.exception_response(frame.unit, frame.function, error.detail)
            self.model.last_error = error.detail
            return rtu.exception_response(frame.unit, frame.function, DEVICE_FAILURE)
        except SlaveError as error:
            code = OPTION_CARD_CODES.get(error.code, error.code) if self.option_card \
                else error.code
            return rtu.exception_response(frame.unit, frame.function, code)

    # -- coils --------------------------------------------------------------------------
    def _coils(self, now_s: float) -> List[bool]:
        model = self.model
        model.advance(now_s)
        words = [model.control_word, model.reference_word, model.status_word(),
                 model.actual_word()]
        return list(words_to_coils(words)) + [model.eeprom_writes]

    def _read_coils(self, data: bytes, now_s: float) -> bytes:
        address, count = rtu.parse_address_count(data)
        if count < 1 or address + count > COIL_COUNT:
            raise SlaveError(ILLEGAL_ADDRESS)
        packed = rtu.pack_coils(self._coils(now_s)[address:address + count])
        return bytes([len(packed)]) + packed

    def _write_coil(self, data: bytes, now_s: float) -> bytes:
        address, value = rtu.parse_address_count(data)
        if value not in (0x0000, 0xFF00):
            raise SlaveError(ILLEGAL_VALUE)
        self._store_coils(address, [value == 0xFF00], now_s)
        return data[:4]

    def _write_coils(self, data: bytes, now_s: float) -> bytes:
        address, count = rtu.parse_address_count(data)
        byte_count = data[4] if len(data) > 4 else -1
        if count < 1 or byte_count != (count + 7) // 8 or len(data) != 5 + byte_count:
            raise SlaveError(ILLEGAL_VALUE)
        coils = [bool(data[5 + i // 8] >> (i % 8) & 1) for i in range(count)]
        self._store_coils(address, coils, now_s)
        return data[:4]

    def _store_coils(self, address: int, coils: List[bool], now_s: float) -> None:
        end = address + len(coils)
        if end > COIL_COUNT or (address < 64 and end > 32):
            raise SlaveError(ILLEGAL_ADDRESS)  # coils 33-64 are the drive's, read-only
        model = self.model
        if address == 64:
            model.eeprom_writes = coils[0]
            return
        current = list(words_to_coils([model.control_word, model.reference_word]))
        current[address:end] = coils
        control_word, reference_word = coils_to_words(current)
        model.write_control(control_word, reference_word, now_s)

    # -- registers ----------------------------------------------------------------------
    def _read_registers(self, data: bytes, now_s: float) -> bytes:
        address, count = rtu.parse_address_count(data)
        if not 1 <= count <= 125:
            raise SlaveError(ILLEGAL_VALUE)
        values = self._register_values(address, count, now_s)
        return bytes([2 * len(values)]) + b''.join(struct.pack('>H', v) for v in values)

    def _register_values(self, address: int, count: int, now_s: float) -> List[int]:
        model = self.model
        model.advance(now_s)
        if self.option_card:
            fixed = {0: model.index, 1: model.card_timeouts[0], 2: model.card_timeouts[1]}
        else:
            fixed = {REGISTER_LAST_ERROR: model.last_error, REGISTER_INDEX: model.index,
                     REGISTER_CTW: model.control_word, REGISTER_REF: model.reference_word,
                     REGISTER_STW: model.status_word(), REGISTER_MAV: model.actual_word()}
        if address in fixed:
            if count != 1:
                raise SlaveError(ILLEGAL_ADDRESS)
            return [fixed[address]]
        return model.read_parameter(self._parameter_number(address), count, now_s)

    def _write_register(self, data: bytes, now_s: float) -> bytes:
        address, value = rtu.parse_address_count(data)
        self._store_registers(address, [value], now_s)
        return data[:4]

    def _write_registers(self, data: bytes, now_s: float) -> bytes:
        address, count = rtu.parse_address_count(data)
        byte_count = data[4] if len(data) > 4 else -1
        if not 1 <= count <= 123 or byte_count != 2 * count or len(data) != 5 + byte_count:
            raise SlaveError(ILLEGAL_VALUE)
        values = list(struct.unpack(f'>{count}H', data[5:5 + byte_count]))
        self._store_registers(address, values, now_s)
        return data[:4]

    def _store_registers(self, address: int, values: List[int], now_s: float) -> None:
        model = self.model
        if self.option_card and address in (0, 1, 2) and len(values) == 1:
            if address == 0:
                model.index = values[0]
            else:
                model.card_timeouts[address - 1] = values[0]
        elif self.option_card:
            model.write_parameter(self._parameter_number(address), values, now_s)
        elif address == REGISTER_INDEX and len(values) == 1:
            model.index = values[0]
        elif address == REGISTER_CTW and len(values) == 1:
            model.write_control(values[0], model.reference_word, now_s)
        elif address == REGISTER_REF and len(values) == 1:
            model.write_control(model.control_word, values[0], now_s)
        else:
            model.write_parameter(self._parameter_number(address), values, now_s)

    @staticmethod
    def _parameter_number(address: int) -> int:
        if (address + 1) % 10:
            raise SlaveError(ILLEGAL_ADDRESS)
        return (address + 1) // 10


def make_drive_device(model: str, now_s: float, **settings: Any) -> FcProfileModbusDevice:
    """Return a simulated drive of ``model`` (settings go to its :class:`FcProfileSimConfig`)."""
    return FcProfileModbusDevice(FcProfileModel(FcProfileSimConfig(model=model, **settings),
                                                now_s))
