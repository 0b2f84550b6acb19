"""
The FC-protocol face of a simulated drive, onto the :class:`FcProfileModel` of the Modbus faces.

So a VLT 5000/6000 or an FC 51 behaves the same whichever protocol talks to it. Every
telegram's PCD1/PCD2 go to :meth:`FcProfileModel.write_control` (the model obeys the control word
only with bit 10, data valid, set, and counts any telegram as keeping the comms timeout
alive: par. 8-03 is "the maximum time between two consecutive telegrams"); every reply
carries the status word in PCD1 and the main actual value in PCD2 (confirmed, "Process
Words"). The parameter channel reads and writes the model's parameters:

=========================  ==================================================================
request                    reply
=========================  ==================================================================
AK 0                       AK 0, PWE 0 (no parameter command)
AK 1 read                  AK 1 (16-bit parameter) or AK 2 (32-bit) with the value
AK 2/14, 3/13 write        AK 1/2 with the value stored (inferred); 13/14 also count an
                           EEPROM store; a word write to a 32-bit parameter or the reverse is
                           error 5 (inferred)
AK 15, IND 04xxh           AK 15 with the text (no padding)
AK 15, IND 05xxh           AK 15 with the text as stored (inferred)
anything else              AK 7, error 253 "request not supported" (FC 101 table; inferred
                           for the VLT)
=========================  ==================================================================

Errors come from the model's :class:`ParameterError`, whose details already are the FC
protocol's codes (the option card passes them through: manual 003 "Exception Codes"): 0 no
such parameter, 1 read-only, 2 out of limits, 5 wrong type, 17 not while running. A numeric
access to a text parameter or a text access to a number is error 5, an AK 15 whose IND high
byte is neither 04h nor 05h error 3 (inferred).
"""

from collections import Counter, deque
from typing import Deque, Optional, Tuple

from drive_bridge.devices.parameters import DATA_TYPES, TEXT
from drive_bridge.protocol import fc_telegram
from drive_bridge.protocol.fc_telegram import FcTelegram
from drive_bridge.protocol.words import join_u32, registers_to_text, text_to_registers
from drive_bridge.sim.fc_profile_model import FcProfileModel
from drive_bridge.sim.fc_profile_parameter_store import ParameterError

MAX_TEXT_REGISTERS = 127


class FcProtocolDevice:
    """Answers FC-protocol telegrams like a drive with par. 500 / 8-30 = FC protocol."""

    def __init__(self, model: FcProfileModel,
                 address_formats: Tuple[str, ...] = fc_telegram.ADDRESS_FORMATS):
        self.model = model
        self.address_formats = tuple(address_formats)
        # (control word, reference) of every telegram received, the latest 1000.
        self.process_received: Deque[Tuple[int, int]] = deque(maxlen=1000)
        self.eeprom_stores: Counter = Counter()  # PNU -> writes with AK 13/14

    def accepts(self, adr: int) -> bool:
        """Return whether this drive listens to telegrams in the format of ``adr``."""
        return fc_telegram.decode_address(adr).address_format in self.address_formats

    def handle(self, telegram: FcTelegram, now_s: float) -> FcTelegram:
        """Act on one telegram addressed to this drive (or broadcast) and return the reply."""
        model = self.model
        self.process_received.append((telegram.pcd1, telegram.pcd2))
        model.write_control(telegram.pcd1, telegram.pcd2, now_s)
        ak, pwe, text = None, 0, None
        if telegram.pke is not None:
            try:
                ak, pwe, text = self._parameter(telegram, now_s)
            except ParameterError as error:
                ak, pwe, text = fc_telegram.AK_REPLY_ERROR, error.detail, None
        model.advance(now_s)
        return fc_telegram.reply_to(telegram, model.status_word(), model.actual_word(), ak, pwe,
                                    text)

    # -- parameter channel --------------------------------------------------------------
    def _parameter(self, telegram: FcTelegram, now_s: float) -> tuple:
        ak, pnu = telegram.ak, telegram.pnu
        self.model.index = telegram.ind
        if ak == fc_telegram.AK_NONE:
            return fc_telegram.AK_REPLY_NONE, 0, None
        if ak == fc_telegram.AK_READ:
            return self._read(pnu, now_s)
        if ak in fc_telegram.WRITE_AKS:
            return self._write(telegram, now_s)
        if ak == fc_telegram.AK_TEXT:
            return self._text(telegram, now_s)
        raise ParameterError(fc_telegram.REQUEST_NOT_SUPPORTED)

    def _read(self, pnu: int, now_s: float) -> tuple:
        if self._is_text(pnu):
            raise ParameterError(fc_telegram.WRONG_DATA_TYPE)
        count = self._registers(pnu)
        registers = self.model.read_parameter(pnu, count, now_s)
        if count == 2:
            return fc_telegram.AK_REPLY_DOUBLE, join_u32(*registers), None
        return fc_telegram.AK_REPLY_WORD, registers[0], None

    def _write(self, telegram: FcTelegram, now_s: float) -> tuple:
        pnu, double = telegram.pnu, telegram.ak in fc_telegram.DOUBLE_WORD_AKS
        model = self.model
        if model.readout(pnu) is not None:
            raise ParameterError(fc_telegram.NO_WRITE_ACCESS)
        if self._exists(pnu) and (self._is_text(pnu) or (self._registers(pnu) == 2) != double):
            raise ParameterError(fc_telegram.WRONG_DATA_TYPE)
        registers = [telegram.pwe >> 16, telegram.pwe & 0xFFFF] if double \
            else [telegram.pwe & 0xFFFF]
        model.write_parameter(pnu, registers, now_s)
        if telegram.ak in fc_telegram.EEPROM_AKS:
            self.eeprom_stores[pnu] += 1
        stored = int(model.parameters[pnu])
        if double:
            return fc_telegram.AK_REPLY_DOUBLE, stored & 0xFFFFFFFF, None
        return fc_telegram.AK_REPLY_WORD, stored & 0xFFFF, None

    def _text(self, telegram: FcTelegram, now_s: float) -> tuple:
        pnu, mode = telegram.pnu, telegram.ind & fc_telegram.TEXT_MODE_MASK
        model = self.model
        if mode not in (fc_telegram.TEXT_READ_INDEX, fc_telegram.TEXT_WRITE_INDEX):
            raise ParameterError(fc_telegram.NO_SUCH_INDEX)
        if not self._is_text(pnu):
            raise ParameterError(fc_telegram.NO_SUCH_PARAMETER if not self._exists(pnu)
                                 else fc_telegram.WRONG_DATA_TYPE)
        if mode == fc_telegram.TEXT_WRITE_INDEX:
            try:
                value = telegram.text_value.decode('latin-1').rstrip('\x00')
                registers = text_to_registers(value, len(value) + len(value) % 2)
            except ValueError:
                raise ParameterError(fc_telegram.OUT_OF_LIMITS) from None
            model.write_parameter(pnu, registers, now_s)
            model.index = fc_telegram.TEXT_READ_INDEX | telegram.ind & 0xFF  # read it back
        registers = model.read_parameter(pnu, MAX_TEXT_REGISTERS, now_s)
        return fc_telegram.AK_REPLY_TEXT, 0, registers_to_text(registers).encode('latin-1')

    # -- parameter facts ----------------------------------------------------------------
    def _value(self, pnu: int) -> Optional[object]:
        value = self.model.readout(pnu)
        return self.model.parameters.get(pnu) if value is None else value

    def _exists(self, pnu: int) -> bool:
        return self._value(pnu) is not None

    def _is_text(self, pnu: int) -> bool:
        spec = self.model.table.get(pnu)
        return isinstance(self._value(pnu), str) or (spec is not None and
                                                     spec.data_type == TEXT)

    def _registers(self, pnu: int) -> int:
        spec = self.model.table.get(pnu)
        if spec is None or spec.data_type == TEXT:
            return 1
        return DATA_TYPES[spec.data_type][0]
