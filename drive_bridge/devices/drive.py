"""
Frequency drives with the Danfoss FC control profile over Modbus RTU: FC 51 and VLT 5000/6000.

One profile class; the families differ only in data (:class:`DriveFamilyData`). The cyclic
exchange takes the fewest transactions the manuals allow: control word and reference written
as coils 1-32 in one function 0F request, status word and main actual value read as coils
33-64 in one function 01 request (manual 004 section 5.2.8, manual 003 "PCD Mapping").

Keepalive and safety: nothing is written to a drive until a command arrives. From the first
acknowledged command on, the control word and reference are rewritten every poll, so the
drive's own control word timeout stops it when the bridge is gone. A drive that goes offline
forgets the command: after it comes back, nothing is written until the next command.
"""

from dataclasses import dataclass
from typing import Callable, Dict, List, Optional, Tuple

from drive_bridge.devices.base import (
    CommandPlan, DeviceReading, ParameterPlan, PollItem, ReadCoils, ReadRegisters, WriteCoil,
    WriteCoils, WriteRegister, WriteRegisters)
from drive_bridge.devices.parameters import (
    decode_value, encode_value, parameter_address, ParameterSpec, TEXT)
from drive_bridge.errors import CommandRefused, ConfigError, DeviceException, ModelMismatch
from drive_bridge.protocol import fc_control, fc_scaling
from drive_bridge.protocol.fc_control import StatusWord
from drive_bridge.protocol.words import coils_to_words, words_to_coils

# The FC-profile process data as coils (both manuals): coil number - 1.
COIL_CONTROL = 0  # coils 1-16 control word, 17-32 reference
COIL_STATUS = 32  # coils 33-48 status word, 49-64 main actual value (output frequency)
PROCESS_COILS = 32
ALWAYS_READ = ('motor_current',)  # every poll; the other readouts take turns


@dataclass(frozen=True)
class DriveFamilyData:
    """Everything that tells one drive family from another; see :mod:`fc` and :mod:`vlt`."""

    name: str
    models: Tuple[str, ...]
    parameters: Dict[int, ParameterSpec]
    readouts: Dict[str, Dict[str, int]]  # model -> readout name -> parameter number
    conversion_factors: Dict[int, float]
    alarm_bits: Dict[int, Tuple[int, str]]  # alarm word bit -> (trip code, name)
    warning_bits: Dict[int, str]
    extended_status_bits: Dict[int, str]
    explain_exception: Callable[..., str]
    detail_register: Optional[int] = None  # read after exception 04 for the detail
    index_register: Optional[int] = None  # array index (FC: register 9; VLT: IND, register 1)
    eeprom_coil: Optional[int] = None  # coil 65: RAM (0) or RAM + EEPROM (1)
    identify_parameter: Optional[int] = None  # a text parameter naming the drive type
    version_parameter: Optional[int] = None
    model_from_type: Callable[[str], Optional[str]] = lambda text: None
    timeout_time_parameter: Optional[int] = None  # FC: 8-03
    timeout_function_parameter: Optional[int] = None  # FC: 8-04
    timeout_register: Optional[int] = None  # VLT: register 2, Modbus comms timeout, 10 ms
    drive_link_timeout_register: Optional[int] = None  # VLT: register 3, card <-> drive
    text_read_index: Optional[int] = None  # VLT: IND = 0x0400 before a text read
    text_write_index: Optional[int] = None  # VLT: IND = 0x0500 before a text write
    parameter_label: Callable[[int], str] = str  # how the manual writes a number (16-14)
    is_setting: Callable[[int], bool] = lambda number: True  # not a readout: backed up

    def spec(self, number: int, data_type: Optional[str] = None,
             conversion: Optional[int] = None) -> ParameterSpec:
        """Return the spec of parameter ``number``, known or as the caller describes it."""
        known = self.parameters.get(number)
        if known is None and data_type is None:
            raise CommandRefused(
                f'parameter {number} is not in the {self.name} table: give its data type '
                '(int16, uint16, int32, uint32, int8, uint8, text) and conversion index')
        name = known.name if known else 'parameter'
        return ParameterSpec(
            number, f'{name} (par. {self.parameter_label(number)})',
            data_type or known.data_type,
            known.conversion if conversion is None and known else (conversion or 0),
            known.source if known else 'given by the caller',
            known.characters if known else 20)


class DriveProfile:
    """FC-profile process data, readouts, commands and parameters of one drive."""

    def __init__(self, data: DriveFamilyData, model: str = 'auto', current_scale: float = 1.0,
                 comms_timeout_s: float = 0.0, comms_timeout_function: int = -1,
                 readout_overrides: Optional[Dict[str, int]] = None,
                 drive_link_timeout_s: float = 0.0):
        if model not in data.models:
            raise ConfigError(f'unknown {data.name} model {model!r}: allowed '
                              f'{", ".join(data.models)}')
        if comms_timeout_function >= 0 and data.timeout_function_parameter is None:
            raise ConfigError(f'comms_timeout_function applies to drives with a control word '
                              f'timeout function parameter (FC 8-04), not {data.name}: leave it '
                              'at -1 and set the drive on the drive')
        if drive_link_timeout_s > 0 and data.drive_link_timeout_register is None:
            raise ConfigError(f'drive_link_timeout applies to the VLT option card (register 3), '
                              f'not {data.name}: leave it at 0')
        for label, seconds in (('comms_timeout', comms_timeout_s),
                               ('drive_link_timeout', drive_link_timeout_s)):
            if data.timeout_register is not None and round(seconds * 100) > 0xFFFF:
                raise ConfigError(f'{label} = {seconds} s does not fit the option card '
                                  'register (10 ms units): allowed up to 655.35 s')
        self.drive_link_timeout_s = drive_link_timeout_s
        self.data = data
        self.family = data.name
        self.configured_model = model
        self.model: Optional[str] = None if model == 'auto' else model
        self.current_scale = current_scale
        self.comms_timeout_s = comms_timeout_s
        self.comms_timeout_function = comms_timeout_function
        self.readout_overrides = dict(readout_overrides or {})
        self.control_word: Optional[int] = None  # None: nothing commanded, no keepalive
        self.reference_pct = 0.0
        self.reference_word = 0
        self.reached_reference = False
        self.identity: Dict[str, str] = {}
        self._identified = data.identify_parameter is None
        self._values: Dict[str, object] = {}
        self._rotation = 0
        self._plan_keys: List[str] = []

    # -- model and readouts -------------------------------------------------------------
    @property
    def default_model(self) -> str:
        """Return the model whose map is used until the drive tells its own."""
        return self.model or next(model for model in self.data.models if model != 'auto')

    @property
    def readouts(self) -> Dict[str, ParameterSpec]:
        """Return readout name -> parameter spec for the resolved model."""
        model = self.default_model
        numbers = dict(self.data.readouts[model], **self.readout_overrides)
        return {name: self.data.spec(number) for name, number in numbers.items()}

    @property
    def commanded_run(self) -> Optional[bool]:
        """Return whether the bridge's control word asks to run (None: nothing sent yet)."""
        if self.control_word is None:
            return None
        return fc_control.is_start(self.control_word)

    def on_offline(self) -> None:
        """Forget the command and every value read: after a reconnect nothing is written."""
        self.control_word = None
        self.reached_reference = False
        self._values.clear()
        self._identified = self.data.identify_parameter is None

    # -- polling ------------------------------------------------------------------------
    def poll_plan(self) -> List[PollItem]:
        """Return one cycle: identify once, keepalive write, status coils, readouts."""
        items: List[PollItem] = []
        if not self._identified:
            for key, number in self._identity_parameters():
                if number is not None:
                    items.append(PollItem(self._read(self.data.spec(number)), key, True))
        if self.control_word is not None:
            items.append(PollItem(self.process_write(self.control_word), 'keepalive'))
        items.append(PollItem(ReadCoils(COIL_STATUS, PROCESS_COILS), 'status'))
        readouts = self.readouts
        for name in ALWAYS_READ:
            if name in readouts:
                items.append(PollItem(self._read(readouts[name]), name))
        rotating = [name for name in readouts if name not in ALWAYS_READ]
        if rotating:
            name = rotating[self._rotation % len(rotating)]
            self._rotation += 1
            items.append(PollItem(self._read(readouts[name]), name))
        self._plan_keys = [item.key for item in items]
        return items

    def follow_up_plan(self, results: list) -> List[PollItem]:
        """After the status read: fetch the alarm/warning word now if the drive trips or warns."""
        status = self._status_from(results)
        if status is None:
            return []
        wanted = []
        if status.tripped:
            wanted.append('alarm_word')
        if status.flag(fc_control.STW_WARNING):
            wanted.append('warning_word')
        readouts = self.readouts
        items = [PollItem(self._read(readouts[name]), name) for name in wanted
                 if name in readouts and name not in self._plan_keys]
        self._plan_keys += [item.key for item in items]
        return items

    def _status_from(self, results: list) -> Optional[StatusWord]:
        for key, result in zip(self._plan_keys, results):
            if key == 'status' and isinstance(result, list):
                return StatusWord(coils_to_words(result[:16])[0])
        return None

    @staticmethod
    def _read(spec: ParameterSpec) -> ReadRegisters:
        return ReadRegisters(spec.address, spec.registers, exact=spec.data_type != TEXT)

    def process_write(self, control_word: int) -> WriteCoils:
        """Return the one write of control word and reference (coils 1-32)."""
        return WriteCoils(COIL_CONTROL, words_to_coils([control_word, self.reference_word]))

    def decode(self, results: list) -> DeviceReading:
        """Decode one cycle's results (aligned with the last plan) into a reading."""
        by_key = dict(zip(self._plan_keys, results))
        if not isinstance(by_key.get('status'), list) or len(by_key['status']) < 32:
            raise ValueError('status coils 33-64 missing from the reply')
        status_word, actual_word = coils_to_words(by_key['status'][:32])
        self._identify(by_key)
        for name, spec in self.readouts.items():
            if isinstance(by_key.get(name), list):
                self._values[name] = decode_value(spec, by_key[name],
                                                  self.data.conversion_factors)
        status = StatusWord(status_word)
        if self.commanded_run and status.flag(fc_control.STW_ON_REFERENCE):
            self.reached_reference = True
        reading = DeviceReading(
            state=status.state(self.commanded_run, self.reached_reference),
            status_word=status_word, speed_feedback_pct=fc_scaling.word_to_percent(actual_word))
        self._fill_readouts(reading)
        self._fill_trip(reading, status)
        self._fill_details(reading, status, actual_word)
        return reading

    def _identity_parameters(self) -> Tuple[Tuple[str, Optional[int]], ...]:
        return (('drive_type', self.data.identify_parameter),
                ('software_version', self.data.version_parameter))

    def _identify(self, by_key: Dict[str, object]) -> None:
        if self._identified:
            return
        for key, number in self._identity_parameters():
            result = by_key.get(key)
            if isinstance(result, list):
                self.identity[key] = str(decode_value(self.data.spec(number), result, {0: 1.0}))
            elif isinstance(result, DeviceException):
                self.identity[key] = f'not readable ({self.data.explain_exception(result.code)})'
        self._identified = True
        type_text = self.identity.get('drive_type', '')
        reported = self.data.model_from_type(type_text) if type_text else None
        if self.configured_model == 'auto':
            self.model = reported or self.default_model
        elif type_text.upper().startswith('FC') and reported != self.configured_model:
            self._identified = False  # ask again after the configuration is fixed
            raise ModelMismatch(
                f'model mismatch: configured {self.configured_model} but the drive reports '
                f'type {type_text!r} (par. {self.data.identify_parameter}); fix the model '
                'parameter or the address')

    def _fill_readouts(self, reading: DeviceReading) -> None:
        values = self._values
        if 'motor_current' in values:
            reading.motor_current_a = float(values['motor_current']) * self.current_scale
        if 'motor_thermal' in values:
            reading.motor_temperature_pct = float(values['motor_thermal'])
        if 'alarm_word' in values:
            reading.alarm_word = int(values['alarm_word'])
        if 'warning_word' in values:
            reading.warning_word = int(values['warning_word'])

    def _fill_trip(self, reading: DeviceReading, status: StatusWord) -> None:
        if not status.tripped:
            return
        code, name = self.trip_from_alarm_word(reading.alarm_word)
        reading.trip_code, reading.trip_name = code, name
        locked = ' (trip locked: cycle the mains power)' if \
            status.flag(fc_control.STW_TRIP_LOCKED) else ''
        reading.fault = f'tripped: {name}{locked}'

    def trip_from_alarm_word(self, alarm_word: Optional[int]) -> Tuple[int, str]:
        """Return (trip code, name) of the first alarm bit set; names of all set bits."""
        if not alarm_word:
            return 0, 'tripped (alarm word not read yet or empty)'
        codes = [self.data.alarm_bits.get(index, (1000 + index, f'alarm word bit {index}'))
                 for index in range(32) if alarm_word >> index & 1]
        return codes[0][0], ', '.join(name for _, name in codes)

    def _fill_details(self, reading: DeviceReading, status: StatusWord,
                      actual_word: int) -> None:
        details = {'model': self.model or self.configured_model}
        details.update(self.identity)
        details.update({name: str(value) for name, value in status.flags().items()})
        details['main_actual_value'] = f'0x{actual_word:04X}'
        details['control_word_sent'] = ('none (no command yet)' if self.control_word is None
                                        else f'0x{self.control_word:04X}')
        details['reference_pct'] = f'{self.reference_pct:g}'
        details['reference_word'] = f'0x{self.reference_word:04X}'
        for name, value in self._values.items():
            details[name] = f'{value:g}' if isinstance(value, float) else str(value)
        reading.warnings.extend(status.warnings())
        if reading.warning_word:
            details['warnings'] = _bit_names(reading.warning_word, self.data.warning_bits)
        extended = self._values.get('extended_status')
        if isinstance(extended, int):
            details['extended_status'] = _bit_names(extended, self.data.extended_status_bits)
        if not status.bus_control:
            reading.warnings.append('local operation: the drive ignores bus commands')
        reading.details = details

    # -- commands -----------------------------------------------------------------------
    def check_command(self, command: str, reading: Optional[DeviceReading]) -> None:
        """Refuse a command the drive would ignore (local operation), before sending."""
        if reading is not None and not StatusWord(reading.status_word).bus_control:
            raise CommandRefused(
                'drive is in local operation (status word bit 9 = 0: Hand on or Off on the '
                'LCP): it ignores bus commands; press Auto on at the drive; nothing sent')

    def command_plan(self, command: str) -> CommandPlan:
        """Return the process-data writes of ``command``; commit the word on acknowledge."""
        if command == 'reset':
            # Reset acts on the rising edge of bit 7; it leaves the drive in ramp stop so a
            # reset never restarts a motor.
            word = fc_control.RAMP_STOP_WORD
            writes = (self.process_write(fc_control.with_reset(word)), self.process_write(word))
        elif command in fc_control.COMMAND_WORDS:
            word = fc_control.COMMAND_WORDS[command]
            writes = (self.process_write(word),)
        else:
            raise CommandRefused(f'drives have no {command} command (allowed: start, stop, '
                                 'quick_stop, coast_stop, reset)')

        def acknowledged() -> None:
            if command == 'start' and not self.commanded_run:
                self.reached_reference = False
            self.control_word = word

        def failed() -> None:
            # A stop was asked for: the keepalive repeats it, never the old run word. A
            # start that failed is not repeated: the keepalive keeps the old word.
            if not fc_control.is_start(word):
                self.control_word = word
        return CommandPlan(command, writes, acknowledged, failed)

    def set_reference(self, percent: float) -> int:
        """Take a speed reference in percent (FC scaling); raise CommandRefused if invalid."""
        try:
            word = fc_scaling.percent_to_word(percent)
        except (ValueError, TypeError) as error:
            raise CommandRefused(f'{error}: nothing sent') from None
        self.reference_pct = float(percent)
        self.reference_word = word
        return word

    # -- set-up writes ------------------------------------------------------------------
    def setup_plan(self) -> List[object]:
        """Return the writes that configure the drive's own comms timeout (none by default)."""
        data = self.data
        writes: List[object] = []
        if self.comms_timeout_s > 0 and data.timeout_time_parameter is not None:
            spec = data.spec(data.timeout_time_parameter)
            writes.append(self._write(spec, encode_value(spec, self.comms_timeout_s,
                                                         data.conversion_factors)))
        if self.comms_timeout_function >= 0 and data.timeout_function_parameter is not None:
            spec = data.spec(data.timeout_function_parameter)
            writes.append(self._write(spec, [self.comms_timeout_function]))
        for register, seconds in ((data.timeout_register, self.comms_timeout_s),
                                  (data.drive_link_timeout_register, self.drive_link_timeout_s)):
            if register is not None and seconds > 0:
                writes.append(WriteRegister(register, round(seconds * 100)))  # 10 ms units
        return writes

    @staticmethod
    def _write(spec: ParameterSpec, registers: list):
        if len(registers) == 1 and spec.data_type != TEXT:
            return WriteRegister(spec.address, registers[0])
        return WriteRegisters(spec.address, tuple(registers))

    # -- parameters ---------------------------------------------------------------------
    def parameter_plan(self, number: int, value=None, data_type: Optional[str] = None,
                       conversion: Optional[int] = None, index: Optional[int] = None,
                       eeprom: bool = False) -> ParameterPlan:
        """Return the transactions reading (value None) or writing parameter ``number``."""
        spec = self.data.spec(number, data_type, conversion)
        parameter_address(number)
        before: List[object] = []
        after: List[object] = []
        index_word = self._index_word(spec, index, value is not None)
        if index_word is not None:
            before.append(WriteRegister(self.data.index_register, index_word))
            if spec.data_type == TEXT and self.data.text_read_index is not None:
                after.append(WriteRegister(self.data.index_register, 0))  # "then cleared"
        if value is None:
            read = self._read(spec)
            factors = self.data.conversion_factors
            return ParameterPlan(f'read {spec.name}', (*before, read, *after),
                                 lambda results: decode_value(spec, results[len(before)],
                                                              factors))
        registers = encode_value(spec, value, self.data.conversion_factors)
        if self.data.eeprom_coil is not None:
            before.insert(0, WriteCoil(self.data.eeprom_coil, bool(eeprom)))
        elif eeprom:
            raise CommandRefused(f'{self.family} drives have no EEPROM store coil')
        return ParameterPlan(f'write {spec.name} = {value!r}',
                             (*before, self._write(spec, registers), *after),
                             lambda results: f'{spec.name} = {value!r} acknowledged')

    def _index_word(self, spec: ParameterSpec, index: Optional[int],
                    write: bool) -> Optional[int]:
        data = self.data
        text_index = data.text_write_index if write else data.text_read_index
        if spec.data_type == TEXT and text_index is not None:
            return text_index | (index or 0)
        if index is None:
            return None
        if data.index_register is None:
            raise CommandRefused(f'{self.family} drives have no array index register')
        if not 0 <= index <= 0xFF:
            raise CommandRefused(f'array index {index} is out of range 0-255')
        return index

    def detail_plan(self, code: int) -> Optional[ReadRegisters]:
        """Return the read that explains exception ``code`` (FC: register 7 after 04)."""
        if code == 4 and self.data.detail_register is not None:
            return ReadRegisters(self.data.detail_register, 1)
        return None

    def explain_exception(self, code: int, detail: Optional[int] = None) -> str:
        """Return technician text for a Modbus exception from the drive."""
        return self.data.explain_exception(code, detail)


def _bit_names(word: int, names: Dict[int, str]) -> str:
    set_bits = [names.get(index, f'bit {index}') for index in range(32) if word >> index & 1]
    return ', '.join(set_bits) or 'none'
