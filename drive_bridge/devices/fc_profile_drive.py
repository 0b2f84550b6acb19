"""
Frequency drives with the Danfoss FC control profile over Modbus RTU: FC 51 and VLT 5000/6000.

One profile class; the families differ only in data (:class:`DriveFamilyData`). The cyclic
exchange takes the fewest transactions the manuals allow: control word and reference written
as coils 1-32 in one function 0F request, status word and main actual value read as coils
33-64 in one function 01 request (manual 004 section 5.2.8, manual 003 "PCD Mapping").

Keepalive and safety: which control word is in force is the bus's motor-state owner's to
decide (:mod:`drive_bridge.bus.motor`); this profile writes what its control view says,
every poll, so the drive's own control word timeout stops it when the bridge is gone, and
nothing while the view has no command in force.
"""

from dataclasses import dataclass, field, replace
from typing import Any, Callable, Dict, FrozenSet, List, Mapping, Optional, Sequence, Tuple

from drive_bridge.devices.contracts import (
    CommandPlan, ControlView, CyclicControl, DeviceProfile, DeviceReading, ParameterAccess,
    ParameterOptions, ParameterPlan, PollCycle, PollShape, PollStep, SetupWrites, SlowReadouts,
    SpeedReference)
from drive_bridge.devices.fc_profile_reading import ALWAYS_READ, DriveReadouts, FcProfileDecoder
from drive_bridge.devices.parameters import (
    decode_value, encode_value, parameter_address, ParameterSpec, TEXT)
from drive_bridge.errors import (
    CommandRefused, ConfigError, DeviceException, ModelMismatch, ProtocolError)
from drive_bridge.protocol import fc_profile, fc_profile_scaling
from drive_bridge.protocol.commands import Command
from drive_bridge.protocol.fc_profile import StatusWord
from drive_bridge.protocol.requests import (
    ReadCoils, ReadRegisters, Request, WriteCoil, WriteCoils, WriteRegister, WriteRegisters)
from drive_bridge.protocol.words import coils_to_words, words_to_coils
from drive_bridge.settings import Setting

# The FC-profile process data as coils (both manuals): coil number - 1.
COIL_CONTROL = 0  # coils 1-16 control word, 17-32 reference
COIL_STATUS = 32  # coils 33-48 status word, 49-64 main actual value (output frequency)
PROCESS_COILS = 32


@dataclass(frozen=True)
class DriveFamilyData:
    """
    Everything that tells one drive family from another.

    See :mod:`~drive_bridge.devices.fc51` and :mod:`~drive_bridge.devices.vlt`.
    """

    name: str
    models: Tuple[str, ...]
    parameters: Dict[int, ParameterSpec]  # every model's parameters together
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
    model_parameters: Dict[str, Dict[int, ParameterSpec]] = field(default_factory=dict)
    # Registers that carry process data or control (never a parameter write; FC: 50000 CTW).
    process_registers: Tuple[int, ...] = ()

    def table(self, model: Optional[str] = None) -> Dict[int, ParameterSpec]:
        """Return the parameter table of ``model`` (the family's when it has one table)."""
        return self.model_parameters.get(model, self.parameters) if model else self.parameters

    def spec(self, number: int, data_type: Optional[str] = None,
             conversion: Optional[int] = None, model: Optional[str] = None) -> ParameterSpec:
        """Return the spec of parameter ``number``, known or as the caller describes it."""
        known = self.table(model).get(number) or self.parameters.get(number)
        if known is None and data_type is None:
            raise CommandRefused(
                f'parameter {number} is not in the {model or self.name} table: give its data '
                'type (int16, uint16, int32, uint32, int8, uint8, text) and conversion index')
        if known is not None and data_type in (None, known.data_type) and \
                conversion in (None, known.conversion):
            return replace(known, name=f'{known.name} (par. {self.parameter_label(number)})')
        name = known.name if known else 'parameter'
        return ParameterSpec(
            number, f'{name} (par. {self.parameter_label(number)})',
            data_type or known.data_type,
            known.conversion if conversion is None and known else (conversion or 0),
            known.source if known else 'given by the caller',
            known.characters if known else 20)

    def settings(self, model: Optional[str] = None) -> List[int]:
        """Return the numbers of the settings a backup saves (readouts excluded)."""
        return sorted(number for number, spec in self.table(model).items() if spec.setting)


def timeout_parameters(drive: 'FcProfileDrive') -> List[Tuple[int, float]]:
    """Return a drive's set-up writes as (parameter number, value): FC 8-03 and 8-04."""
    data = drive.data
    writes: List[Tuple[int, float]] = []
    if drive.comms_timeout_s > 0 and data.timeout_time_parameter is not None:
        writes.append((data.timeout_time_parameter, drive.comms_timeout_s))
    if drive.comms_timeout_function >= 0 and data.timeout_function_parameter is not None:
        writes.append((data.timeout_function_parameter, drive.comms_timeout_function))
    return writes


def control_word_for(steady: Optional[Command]) -> Optional[int]:
    """Return the FC-profile control word that carries ``steady`` (None: write nothing)."""
    if steady is None:
        return None
    return fc_profile.COMMAND_WORDS.get(steady, fc_profile.RAMP_STOP_WORD)


class FcProfileDrive(DeviceProfile, CyclicControl, SpeedReference, SetupWrites):
    """
    What every FC-profile drive shares, whatever carries its telegrams (Modbus, FC protocol).

    Model and identity, and the commands' control words and the reference scaling; its
    readouts are a :class:`~drive_bridge.devices.fc_profile_reading.DriveReadouts`
    (``readout_set``), the decode of a poll a
    :class:`~drive_bridge.devices.fc_profile_reading.FcProfileDecoder` (``decoder``).
    Subclasses say how the data travels.
    """

    commands = frozenset({Command.START, Command.STOP, Command.QUICK_STOP, Command.COAST_STOP,
                          Command.RESET})

    def __init__(self, data: DriveFamilyData, model: str = 'auto', current_scale: float = 1.0,
                 comms_timeout_s: float = 0.0, comms_timeout_function: int = -1,
                 readout_overrides: Optional[Dict[str, int]] = None,
                 slow_readouts: Optional[SlowReadouts] = None):
        if model not in data.models:
            raise ConfigError(f'unknown {data.name} model {model!r}: allowed '
                              f'{", ".join(data.models)}')
        if comms_timeout_function >= 0 and data.timeout_function_parameter is None:
            raise ConfigError(f'comms_timeout_function applies to drives with a control word '
                              f'timeout function parameter (FC 8-04), not {data.name}: leave it '
                              'at -1 and set the drive on the drive')
        super().__init__(model)
        self.data = data
        self.family = data.name
        self.current_scale = current_scale
        self.comms_timeout_s = comms_timeout_s
        self.comms_timeout_function = comms_timeout_function
        self.identity: Dict[str, str] = {}
        self._identified = data.identify_parameter is None
        self.readout_set = DriveReadouts(
            data.readouts, lambda number, on_model: data.spec(number, model=on_model),
            readout_overrides, slow_readouts)
        self.decoder = FcProfileDecoder(data.alarm_bits, data.warning_bits,
                                        data.extended_status_bits, current_scale)
        self.read = self.readout_set.read  # the readouts, each with the poll that read it
        self.slow_readouts = self.readout_set.slow_readouts

    # -- model and readouts -------------------------------------------------------------
    @property
    def default_model(self) -> str:
        """Return the model whose map is used until the drive tells its own."""
        return self.resolved_model or next(model for model in self.data.models
                                           if model != 'auto')

    @property
    def readouts(self) -> Dict[str, ParameterSpec]:
        """Return readout name -> parameter spec for the resolved model."""
        return self.readout_set.of_model(self.default_model)

    @property
    def reading_fields(self) -> FrozenSet[str]:
        """Return speed feedback and the readouts this model has (current, thermal, words)."""
        return self.readout_set.fields(self.default_model)

    def on_offline(self) -> None:
        """Forget every value read: the drive may come back as another one."""
        self.decoder.forget()
        self.readout_set.forget()
        self._identified = self.data.identify_parameter is None

    def next_rotating_readout(self, now_s: float) -> Optional[str]:
        """Return the slow readout whose turn it is, one a readout period, if one is due."""
        return self.readout_set.next_rotating(self.default_model, now_s)

    def take_status(self, status: StatusWord, read: List[str]) -> List[str]:
        """
        Note the status word just read; return the readouts to fetch at once (not in ``read``).

        Those a status bit witnesses (:func:`~drive_bridge.devices.fc_profile_reading.witnesses`)
        when the bit is set (trip, warning) or when the value read is older than the bit's
        present value.
        """
        return self.readout_set.take_status(self.default_model, status, read)

    def take_readout(self, name: str, value: object) -> None:
        """Keep the decoded value of readout ``name`` (display units), read in this poll."""
        self.readout_set.take(name, value)

    def current(self, name: str) -> object:
        """Return readout ``name`` as last read, or None where its status bit changed since."""
        return self.readout_set.current(name)

    # -- identity -----------------------------------------------------------------------
    def identity_parameters(self) -> Tuple[Tuple[str, int], ...]:
        """Return the (key, parameter) pairs still to read to identify the drive."""
        if self._identified:
            return ()
        pairs = (('drive_type', self.data.identify_parameter),
                 ('software_version', self.data.version_parameter))
        return tuple((key, number) for key, number in pairs if number is not None)

    def take_identity(self, results: Dict[str, object]) -> None:
        """Take the identity replies (text, or the error that refused the read)."""
        if self._identified:
            return
        for key, result in results.items():
            if isinstance(result, DeviceException):
                self.identity[key] = f'not readable ({self.explain_exception(result.code)})'
            elif result is not None:
                self.identity[key] = str(result)
        self._identified = True
        type_text = self.identity.get('drive_type', '')
        reported = self.data.model_from_type(type_text) if type_text else None
        if self.configured_model == 'auto':
            self.resolved_model = reported or self.default_model
        elif type_text.upper().startswith('FC') and reported != self.configured_model:
            self._identified = False  # ask again after the configuration is fixed
            raise ModelMismatch(
                f'model mismatch: configured {self.configured_model} but the drive reports '
                f'type {type_text!r} (par. {self.data.identify_parameter}); fix the model '
                'parameter or the address')

    # -- decode -------------------------------------------------------------------------
    def reading(self, status_word: int, actual_word: int, control: ControlView) -> DeviceReading:
        """Return the reading of one poll from its status word, actual value and readouts."""
        reference_pct = fc_profile_scaling.word_to_percent(control.reference_word)
        return self.decoder.reading(
            status_word, actual_word, control.steady,
            self.readout_set.values(self.default_model), {'model': self.model, **self.identity},
            {'control_word_sent': self.describe_control(control),
             'reference_word': f'0x{control.reference_word:04X}',
             'reference_pct': f'{reference_pct:g}'})

    def trip_from_alarm_word(self, alarm_word: Optional[int]) -> Tuple[int, str]:
        """Return (trip code, names of the set bits); unknown code while no bit is read."""
        return self.decoder.trip_from_alarm_word(alarm_word)

    def describe_control(self, control: ControlView) -> str:
        """Return the control word the keepalive writes, in words."""
        word = control_word_for(control.steady)
        return 'none (no command yet)' if word is None else f'0x{word:04X}'

    # -- commands -----------------------------------------------------------------------
    def check_command(self, command: Command, reading: Optional[DeviceReading]) -> None:
        """Refuse a command the drive would ignore (local operation), before sending."""
        if reading is not None and not StatusWord(reading.status_word).bus_control:
            raise CommandRefused(
                'drive is in local operation (status word bit 9 = 0: Hand on or Off on the '
                'LCP): it ignores bus commands; press Auto on at the drive; nothing sent')

    def command_words(self, command: Command) -> Tuple[int, ...]:
        """
        Return the control words that carry out ``command``, in order.

        Reset acts on the rising edge of bit 7 and leaves the drive in ramp stop, so a
        reset never restarts a motor.
        """
        if command is Command.RESET:
            word = fc_profile.RAMP_STOP_WORD
            return fc_profile.with_reset(word), word
        word = fc_profile.COMMAND_WORDS.get(command)
        if word is None:
            raise CommandRefused(f'drives have no {command.value} command (allowed: start, '
                                 'stop, quick_stop, coast_stop, reset)')
        return (word,)

    def reference_word(self, percent: float) -> int:
        """Return the reference word of ``percent`` (FC scaling); raise CommandRefused."""
        try:
            return fc_profile_scaling.percent_to_word(percent)
        except (ValueError, TypeError) as error:
            raise CommandRefused(f'{error}: nothing sent') from None

    def explain_exception(self, code: int, detail: Optional[int] = None) -> str:
        """Return technician text for a refusal code from the drive."""
        return self.data.explain_exception(code, detail)


class FcProfileModbusDrive(FcProfileDrive, ParameterAccess):
    """
    An FC-profile drive over Modbus RTU: FC 51 built-in, VLT 5000/6000 option card.

    One cycle: identify once, the keepalive write of coils 1-32 (control word and
    reference) when a command is in force, the status coils 33-64, motor current, one
    rotating readout, and the alarm/warning word at once when the status word shows a trip
    or a warning.
    """

    def __init__(self, data: DriveFamilyData, model: str = 'auto', current_scale: float = 1.0,
                 comms_timeout_s: float = 0.0, comms_timeout_function: int = -1,
                 readout_overrides: Optional[Dict[str, int]] = None,
                 slow_readouts: Optional[SlowReadouts] = None,
                 drive_link_timeout_s: float = 0.0):
        if drive_link_timeout_s > 0 and data.drive_link_timeout_register is None:
            raise ConfigError(f'drive_link_timeout applies to the VLT option card (register 3), '
                              f'not {data.name}: leave it at 0')
        for label, seconds in (('comms_timeout', comms_timeout_s),
                               ('drive_link_timeout', drive_link_timeout_s)):
            if data.timeout_register is not None and round(seconds * 100) > 0xFFFF:
                raise ConfigError(f'{label} = {seconds} s does not fit the option card '
                                  'register (10 ms units): allowed up to 655.35 s')
        super().__init__(data, model, current_scale, comms_timeout_s, comms_timeout_function,
                         readout_overrides, slow_readouts)
        self.drive_link_timeout_s = drive_link_timeout_s

    # -- polling ------------------------------------------------------------------------
    def poll(self, control: ControlView, now_s: float) -> PollCycle:
        """Return one cycle (see the class docstring)."""
        self.read.begin_poll()
        identity = {}
        for key, number in self.identity_parameters():
            identity[key] = yield PollStep(self._read(self.data.spec(number)), optional=True)
        self.take_identity({key: self._identity_value(key, result)
                            for key, result in identity.items()})
        word = control_word_for(control.steady)  # built now: what is in force at this moment
        if word is not None:
            yield PollStep(self.process_write(word, control.reference_word), optional=True,
                           retry=False)
        coils = yield PollStep(ReadCoils(COIL_STATUS, PROCESS_COILS), stamps=True)
        if not isinstance(coils, list) or len(coils) < PROCESS_COILS:
            raise ProtocolError('status coils 33-64 missing from the reply')
        status_word, actual_word = coils_to_words(coils[:PROCESS_COILS])
        read = [name for name in ALWAYS_READ if name in self.readouts]
        rotating = self.next_rotating_readout(now_s)
        if rotating is not None:
            read.append(rotating)
        read += self.take_status(StatusWord(status_word), read)
        for name in read:
            spec = self.readouts[name]
            registers = yield PollStep(self._read(spec))
            self.take_readout(name, decode_value(spec, registers, self.data.conversion_factors))
        return self.reading(status_word, actual_word, control)

    def poll_shape(self) -> PollShape:
        """
        Keepalive, status coils, current, a slow readout, alarm and warning word at once.

        Each time it comes online: the identity reads and the set-up writes.
        """
        identity = sum(1 for number in (self.data.identify_parameter,
                                        self.data.version_parameter) if number is not None)
        return PollShape(transactions=6, writes=1, online=identity + len(self.setup_plan()))

    def _identity_value(self, key: str, result: object) -> object:
        if not isinstance(result, list):
            return result
        number = dict(self.identity_parameters())[key]
        return decode_value(self.data.spec(number), result, {0: 1.0})

    @staticmethod
    def _read(spec: ParameterSpec) -> ReadRegisters:
        return ReadRegisters(spec.address, spec.registers, exact=spec.data_type != TEXT)

    def process_write(self, control_word: int, reference_word: int) -> WriteCoils:
        """Return the one write of control word and reference (coils 1-32)."""
        return WriteCoils(COIL_CONTROL, words_to_coils([control_word, reference_word]))

    def command_plan(self, command: Command, control: ControlView) -> CommandPlan:
        """Return the process-data writes of ``command`` (with the reference in force)."""
        return CommandPlan(command, tuple(self.process_write(word, control.reference_word)
                                          for word in self.command_words(command)))

    # -- set-up writes ------------------------------------------------------------------
    def setup_plan(self) -> List[Request]:
        """Return the writes that configure the drive's own comms timeout (none by default)."""
        return [request for _, request in self._setup_writes()]

    def setup_labels(self) -> List[str]:
        """Return each set-up write by parameter or register: ``par. 8-03 ... = 5.5``."""
        return [label for label, _ in self._setup_writes()]

    def _setup_writes(self) -> List[Tuple[str, Request]]:
        data = self.data
        writes: List[Tuple[str, Request]] = []
        for number, value in timeout_parameters(self):
            spec = data.spec(number)
            registers = encode_value(spec, value, data.conversion_factors) \
                if number == data.timeout_time_parameter else [value]
            writes.append((f'{spec.name} = {value:g}', self._write(spec, registers)))
        for register, seconds, name in (
                (data.timeout_register, self.comms_timeout_s, 'Modbus communications timeout'),
                (data.drive_link_timeout_register, self.drive_link_timeout_s,
                 'drive communications timeout')):
            if register is not None and seconds > 0:
                writes.append((f'option card register {register + 1} ({name}) = {seconds:g} s',
                               WriteRegister(register, round(seconds * 100))))  # 10 ms units
        return writes

    @staticmethod
    def _write(spec: ParameterSpec, registers: list) -> Request:
        if len(registers) == 1 and spec.data_type != TEXT:
            return WriteRegister(spec.address, registers[0])
        return WriteRegisters(spec.address, tuple(registers))

    # -- parameters ---------------------------------------------------------------------
    def parameter_plan(self, number: int, value: Any = None,
                       options: ParameterOptions = ParameterOptions()) -> ParameterPlan:
        """Return the transactions reading (value None) or writing parameter ``number``."""
        spec = self.data.spec(number, options.data_type, options.conversion, self.default_model)
        if parameter_address(number) in self.data.process_registers:
            raise CommandRefused(f'parameter {number}: its register carries process data or '
                                 'control (control word, reference, status): not a parameter; '
                                 'use the commands and the speed reference')
        before: List[Request] = []
        after: List[Request] = []
        index_word = self._index_word(spec, options.index, value is not None)
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
            before.insert(0, WriteCoil(self.data.eeprom_coil, bool(options.eeprom)))
        elif options.eeprom:
            raise CommandRefused(f'{self.family} drives have no EEPROM store coil')
        return ParameterPlan(f'write {spec.name} = {value!r}',
                             (*before, self._write(spec, registers), *after),
                             lambda results: f'{spec.name} = {value!r} acknowledged')

    def parameter_numbers(self) -> Sequence[int]:
        """Return the settings of the model's table (readouts excluded)."""
        return self.data.settings(self.default_model)

    def parameter_table(self) -> Mapping[int, ParameterSpec]:
        """Return the model's parameter table."""
        return self.data.table(self.default_model)

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

    def detail_request(self, code: int) -> Optional[Request]:
        """Return the read that explains exception ``code`` (FC: register 7 after 04)."""
        if code == 4 and self.data.detail_register is not None:
            return ReadRegisters(self.data.detail_register, 1)
        return None


# Device settings every FC-profile drive family takes (beyond the common ones).
COMMS_TIMEOUT = Setting(
    'comms_timeout', float, 0.0,
    "drives: the drive's own control word timeout in seconds, written when the drive comes "
    'online (FC: par. 8-03; VLT option card: register 2); 0 = leave the drive as set',
    low=0.0, high=6000.0)
CURRENT_PARAMETER = Setting(
    'current_parameter', int, 0,
    "drives: parameter number of the motor current readout; 0 = the model's own (FC 51: "
    '1614 = 16-14; VLT 5000: 520; VLT 6000: 514)', low=0, high=6553)


def make_drive_profile(data: DriveFamilyData) -> Callable[[str, str, Mapping[str, Any]],
                                                          DeviceProfile]:
    """Return the profile factory of a drive family (Modbus RTU: :class:`FcProfileModbusDrive`)."""
    def make(model: str, protocol: str, options: Mapping[str, Any]) -> DeviceProfile:
        overrides = {'motor_current': options['current_parameter']} \
            if options.get('current_parameter') else {}
        common = (data, model, options.get('current_scale', 1.0),
                  options.get('comms_timeout', 0.0), options.get('comms_timeout_function', -1),
                  overrides, SlowReadouts(options.get('readout_period', 0.0)))
        if protocol == 'fc_protocol':
            from drive_bridge.devices.fc_protocol_drive import FcProtocolDriveProfile
            if options.get('drive_link_timeout', 0.0) > 0:
                raise ConfigError("drive_link_timeout is the Modbus option card's register 3: "
                                  'on the FC protocol there is no card; leave it at 0')
            return FcProtocolDriveProfile(*common)
        return FcProfileModbusDrive(*common, options.get('drive_link_timeout', 0.0))
    return make
