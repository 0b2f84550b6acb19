"""
An FC-profile drive over the Danfoss FC protocol: VLT 5000/6000 (par. 500) and FC 51 (8-30).

The drive's own RS-485 protocol, no option card (:mod:`drive_bridge.protocol.fc_telegram`).
One telegram per poll does everything the Modbus path needs three or four transactions for:
its process block carries the control word and reference in and brings the status word and
main actual value back, and its parameter channel reads one readout (motor current every
other poll, the slow readouts in turn in between, the alarm word at once after a trip).

The control word is the one in force (the bus's motor-state owner decides it): with nothing
in force the telegram carries control word 0, whose bit 10 ("data valid") is clear, so the
drive ignores it (manual 004 5.6.2, manual 003: the option card sends parameter accesses with
the process data "deactivated"). Such a telegram changes nothing in the drive, which is how a
monitor-only drive is read. Parameter accesses (commissioning, set-up) carry that ignored
control word too: a job queued earlier can never carry a stale run word.

Parameter values travel in PWE: one word for 8- and 16-bit types, a double word for 32-bit
types, text with AK 15 (IND high byte 04h to read, 05h to write). A refusal is an AK 7 reply
with the drive's error code (:func:`~drive_bridge.protocol.fc_telegram.explain_error`); its
process block is still valid, so a refused readout does not lose the poll's status word.
"""

from typing import Any, Dict, List, Mapping, Optional, Sequence

from drive_bridge.devices.contracts import (
    CommandPlan, ControlView, ParameterAccess, ParameterOptions, ParameterPlan, PollCycle,
    PollShape, PollStep, SlowReadouts)
from drive_bridge.devices.fc_profile_drive import (
    control_word_for, DriveFamilyData, FcProfileDrive, timeout_parameters)
from drive_bridge.devices.fc_profile_reading import ALWAYS_READ
from drive_bridge.devices.parameters import (
    DATA_TYPES, decode_value, encode_value, ParameterSpec, TEXT)
from drive_bridge.errors import CommandRefused, ConfigError, DeviceException, ProtocolError
from drive_bridge.protocol import fc_telegram
from drive_bridge.protocol.commands import Command
from drive_bridge.protocol.fc_profile import StatusWord
from drive_bridge.protocol.fc_telegram import FcTelegram, FcTelegramRequest
from drive_bridge.protocol.requests import Request

IGNORED_CONTROL_WORD = 0  # bit 10 clear: the drive ignores control word and reference


class FcProtocolDriveProfile(FcProfileDrive, ParameterAccess):
    """One FC-profile drive on an FC-protocol line; see the module docstring."""

    def __init__(self, data: DriveFamilyData, model: str = 'auto', current_scale: float = 1.0,
                 comms_timeout_s: float = 0.0, comms_timeout_function: int = -1,
                 readout_overrides: Optional[Dict[str, int]] = None,
                 slow_readouts: Optional[SlowReadouts] = None):
        if comms_timeout_s > 0 and data.timeout_time_parameter is None:
            raise ConfigError(
                f'comms_timeout: a {data.name} drive on the FC protocol has no option card '
                "register for it; set the drive's own bus timeout at the drive (VLT 5000/6000: "
                'par. 555 and 556, check your manual) and leave comms_timeout at 0')
        super().__init__(data, model, current_scale, comms_timeout_s, comms_timeout_function,
                         readout_overrides, slow_readouts)
        self._turn = 0
        self._follow_up: List[str] = []

    # -- polling ------------------------------------------------------------------------
    def poll(self, control: ControlView, now_s: float) -> PollCycle:
        """One telegram: control word and reference in, status and one readout back."""
        self.read.begin_poll()
        identity = {}
        for key, number in self.identity_parameters():
            result = yield PollStep(self._read_request(self.data.spec(number)), optional=True)
            identity[key] = self._identity_value(number, result)
        self.take_identity(identity)
        name = self._next_readout(now_s)
        spec = self.readouts[name]
        word = control_word_for(control.steady)  # built now: what is in force at this moment
        request = self._read_request(spec, IGNORED_CONTROL_WORD if word is None else word,
                                     control.reference_word)
        reply = yield PollStep(request, optional=True,  # a refused read still has the status
                               stamps=True)
        if isinstance(reply, DeviceException) and isinstance(reply.reply, FcTelegram):
            # An AK 7 reply: the drive refused the read, its process block is valid.
            self.take_readout_error(name, reply)
            reply = reply.reply
        elif not isinstance(reply, FcTelegram):
            raise ProtocolError('no telegram in the reply')
        else:
            self.take_readout(name, self._value(spec, reply))
        status = StatusWord(reply.pcd1)
        self._follow_up = self.take_status(status, [name])
        return self.reading(reply.pcd1, reply.pcd2, control)

    def poll_shape(self) -> PollShape:
        """One telegram a poll; the identity reads and set-up writes each time it comes back."""
        identity = sum(1 for number in (self.data.identify_parameter,
                                        self.data.version_parameter) if number is not None)
        return PollShape(transactions=1, online=identity + len(self.setup_plan()))

    def _next_readout(self, now_s: float) -> str:
        """Return the readout whose turn it is: follow-ups, then current and slow ones."""
        if self._follow_up:
            return self._follow_up.pop(0)
        self._turn += 1
        current = [name for name in ALWAYS_READ if name in self.readouts]
        if current and self._turn % 2:  # the current at least every other telegram
            return current[0]
        return self.next_rotating_readout(now_s) or current[0]

    def take_readout_error(self, name: str, error: DeviceException) -> None:
        """Note a readout the drive refused (the reading goes on without it)."""
        self.identity[f'{name}_error'] = self.explain_exception(error.code)
        self.read.drop(name)  # not current, nor asked for again but by its turn or its bit

    def _identity_value(self, number: int, result: Any) -> Any:
        if isinstance(result, FcTelegram):
            return self._value(self.data.spec(number), result)
        return result

    @staticmethod
    def _read_request(spec: ParameterSpec, control_word: int = IGNORED_CONTROL_WORD,
                      reference: int = 0, index: int = 0) -> FcTelegramRequest:
        if spec.data_type == TEXT:
            return fc_telegram.read_text_request(spec.number, index, control_word, reference)
        return fc_telegram.read_parameter_request(spec.number, index, control_word, reference)

    def _value(self, spec: ParameterSpec, reply: FcTelegram) -> Any:
        """Return the value a reply carries for ``spec``, in display units."""
        if spec.data_type == TEXT:
            return reply.text_value.decode('latin-1').rstrip('\x00 ')
        registers = DATA_TYPES[spec.data_type][0]
        words = [reply.pwe >> 16 & 0xFFFF, reply.pwe & 0xFFFF] if registers == 2 \
            else [reply.pwe & 0xFFFF]
        return decode_value(spec, words, self.data.conversion_factors)

    # -- commands -----------------------------------------------------------------------
    def command_plan(self, command: Command, control: ControlView) -> CommandPlan:
        """Return the process telegrams of ``command`` (with the reference in force)."""
        return CommandPlan(command, tuple(fc_telegram.process_request(word, control.reference_word)
                                          for word in self.command_words(command)))

    def describe_control(self, control: ControlView) -> str:
        """Return the control word the poll telegram carries, in words."""
        word = control_word_for(control.steady)
        return '0x0000 (data not valid: ignored by the drive)' if word is None \
            else f'0x{word:04X}'

    # -- set-up writes ------------------------------------------------------------------
    def setup_plan(self) -> List[Request]:
        """Return the writes of the drive's own control word timeout (FC: 8-03, 8-04)."""
        return [self._write_request(self.data.spec(number), value)
                for number, value in timeout_parameters(self)]

    def setup_labels(self) -> List[str]:
        """Return each set-up write by parameter: ``... (par. 8-03) = 5.5``."""
        return [f'{self.data.spec(number).name} = {value:g}'
                for number, value in timeout_parameters(self)]

    # -- parameters ---------------------------------------------------------------------
    def parameter_plan(self, number: int, value: Any = None,
                       options: ParameterOptions = ParameterOptions()) -> ParameterPlan:
        """Return the telegram reading (value None) or writing parameter ``number``."""
        spec = self.data.spec(number, options.data_type, options.conversion, self.default_model)
        if not 0 < number <= fc_telegram.PNU_MASK:
            raise CommandRefused(f'parameter {number} has no FC-protocol number (PNU 1-4095)')
        index = options.index or 0
        if value is None:
            request = self._read_request(spec, index=index)
            return ParameterPlan(f'read {spec.name}', (request,),
                                 lambda results: self._value(spec, results[0]))
        request = self._write_request(spec, value, options.eeprom, index)
        return ParameterPlan(f'write {spec.name} = {value!r}', (request,),
                             lambda results: f'{spec.name} = {value!r} acknowledged')

    def _write_request(self, spec: ParameterSpec, value: Any, eeprom: bool = False,
                       index: int = 0) -> FcTelegramRequest:
        try:
            if spec.data_type == TEXT:
                if not isinstance(value, str):
                    value = str(value)
                if len(value) > spec.characters:
                    raise CommandRefused(f'{spec.name}: {value!r} is longer than '
                                         f'{spec.characters} characters')
                return fc_telegram.write_text_request(spec.number, value, index)
            words = encode_value(spec, value, self.data.conversion_factors)
            double = len(words) == 2
            raw = words[0] << 16 | words[1] if double else words[0]
            return fc_telegram.write_parameter_request(spec.number, raw, double, eeprom, index)
        except ProtocolError as error:
            raise CommandRefused(f'{spec.name}: {error}') from None

    def parameter_numbers(self) -> Sequence[int]:
        """Return the settings of the model's table (readouts excluded)."""
        return self.data.settings(self.default_model)

    def parameter_table(self) -> Mapping[int, ParameterSpec]:
        """Return the model's parameter table."""
        return self.data.table(self.default_model)

    def explain_exception(self, code: int, detail: Optional[int] = None) -> str:
        """Return technician text for the error code of an AK 7 reply."""
        return fc_telegram.explain_error(code)
