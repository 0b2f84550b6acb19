"""
The parameters of a simulated FC-profile drive: stored values and their register access.

The drive model (:class:`~drive_bridge.sim.fc_profile_model.FcProfileModel`) owns the behaviour
and the live readouts; this store owns every settable parameter's raw value, how many
registers each takes, the text parameters and the option card's index register (IND), and
answers a read or a write with the detail code of register 7 when it fails (manual 004
section 5.3.2). The model hands it what only the model knows: a readout's live value,
whether the output runs.
"""

from typing import Dict, Mapping, Optional

from drive_bridge.devices import fc51, vlt
from drive_bridge.devices.parameters import DATA_TYPES, ParameterSpec, TEXT
from drive_bridge.protocol.words import join_u32, registers_to_text, text_to_registers

# Detail codes of register 7 (manual 004 section 5.3.2).
NO_SUCH_PARAMETER, NO_WRITE_ACCESS, VALUE_OUT_OF_LIMITS = 0, 1, 2
TYPE_MISMATCH, NOT_IN_THIS_MODE = 5, 17
# Parameters that cannot change while the output runs: motor current (FC 1-24), VLT 104.
LOCKED_WHILE_RUNNING = (124, 104)
MAX_TEXT_WRITE_REGISTERS = 10


class ParameterError(Exception):
    """A parameter access fails: exception 04 with ``detail`` in register 7."""

    def __init__(self, detail: int):
        super().__init__(fc51.LAST_ERROR_DETAILS.get(detail, str(detail)))
        self.detail = detail


class FcProfileParameterStore:
    """
    Every stored parameter of one simulated drive, by number, in raw units.

    ``configured``: values the drive's configuration sets; every other setting of ``table``
    starts at its default (else its minimum); ``extra`` overrides both. ``maxima``: the
    highest raw value a parameter accepts, where the table does not say (FC: par. 8-04).
    ``option_card``: the VLT option card, whose text accesses need IND set first and whose
    text reads are space-filled to the request.
    """

    def __init__(self, table: Dict[int, ParameterSpec], conversion_factors: Mapping[int, float],
                 configured: Mapping[int, object], extra: Mapping[int, object],
                 maxima: Mapping[int, int], option_card: bool):
        self.table = table
        self.values: Dict[int, object] = dict(configured)
        for number, spec in table.items():  # every setting of the table has a value
            if spec.setting:
                self.values.setdefault(number, initial_raw(spec, conversion_factors))
        self.values.update(extra)
        self.maxima = dict(maxima)
        self.option_card = option_card
        self.index = 0  # FC: register 9; option card: IND, register 1

    def read(self, number: int, count: int, live: Optional[object] = None) -> list:
        """Return ``count`` registers of parameter ``number`` (``live``: a readout's value)."""
        value = self.values.get(number) if live is None else live
        if value is None:
            raise ParameterError(NO_SUCH_PARAMETER)
        if isinstance(value, str):
            self._check_text_mode(vlt.TEXT_READ_INDEX)
            stored = text_to_registers(value, len(value) + len(value) % 2)
            if self.option_card:  # manual 003 "Text Blocks": space filled to the request
                return (stored + [0x2020] * count)[:count]
            # Manual 004 section 5.4.4: a longer request gets a truncated answer.
            return stored[:count]
        registers = self.register_count(number)
        if count > registers:
            raise ParameterError(TYPE_MISMATCH)
        raw = int(value) & (0xFFFFFFFF if registers == 2 else 0xFFFF)
        return ([raw >> 16, raw & 0xFFFF] if registers == 2 else [raw])[:count]

    def write(self, number: int, registers: list, is_readout: bool, running: bool) -> None:
        """Store a write to parameter ``number``; raise ParameterError with its detail."""
        if is_readout:
            raise ParameterError(NO_WRITE_ACCESS)
        if number not in self.values:
            raise ParameterError(NO_SUCH_PARAMETER)
        spec = self.table.get(number)
        if spec is not None and spec.data_type == TEXT:
            self._check_text_mode(vlt.TEXT_WRITE_INDEX)
            if len(registers) > MAX_TEXT_WRITE_REGISTERS:
                raise ParameterError(VALUE_OUT_OF_LIMITS)
            self.values[number] = registers_to_text(registers)
            return
        if len(registers) != self.register_count(number):
            raise ParameterError(TYPE_MISMATCH)
        value = join_u32(*registers) if len(registers) == 2 else registers[0]
        if value > self.maxima.get(number, value):
            raise ParameterError(VALUE_OUT_OF_LIMITS)
        if number in LOCKED_WHILE_RUNNING and running:
            raise ParameterError(NOT_IN_THIS_MODE)
        self.values[number] = value

    def register_count(self, number: int) -> int:
        """Return how many registers parameter ``number`` takes (a text: 1 per access)."""
        spec = self.table.get(number)
        if spec is None or spec.data_type == TEXT:
            return 1
        return DATA_TYPES[spec.data_type][0]

    def _check_text_mode(self, mode: int) -> None:
        """Option card: a text access needs IND = 0x0400 (read) or 0x0500 (write) first."""
        if self.option_card and self.index & 0xFF00 != mode:
            raise ParameterError(TYPE_MISMATCH)


def initial_raw(spec: ParameterSpec, factors: Mapping[int, float]) -> object:
    """Return the raw value a simulated drive starts with: the default, else the minimum."""
    if spec.data_type == TEXT:
        return str(spec.default or '')
    value = spec.default if spec.default is not None else spec.minimum
    if value is None:
        value = min(spec.options) if spec.options else 0
    return round(value / factors.get(spec.conversion, 1.0))
