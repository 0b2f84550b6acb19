"""
MCD soft starters: MCD 201/202/500 via the MCD Modbus Module, MCD 3000 via the Remote Operator.

Every table here comes from the manual ``000_b701c31669ff8873.txt`` ("Installation
Instructions: MCD Modbus Module", order code 175G9000); each names its section.
Register numbers are the manual's 1-based numbers; the frame address is number - 1.
"""

from dataclasses import dataclass
from typing import Any, Dict, FrozenSet, List, Mapping, Optional, Sequence, Tuple

from drive_bridge.devices.contracts import (
    CommandPlan, ControlView, DeviceProfile, DeviceReading, Family, ParameterAccess,
    ParameterOptions, ParameterPlan, PollCycle, PollStep, SlowReadouts, TRIP_CODE_UNKNOWN)
from drive_bridge.errors import CommandRefused, ConfigError, ModelMismatch, ProtocolError
from drive_bridge.protocol.commands import Command
from drive_bridge.protocol.requests import ReadRegisters, WriteRegister
from drive_bridge.protocol.words import bit, bits
from drive_bridge.settings import Setting

FAMILY = 'mcd'
MODELS = ('auto', 'mcd201', 'mcd202', 'mcd500', 'mcd3000')
# What sets an MCD's address, and its range (manual 000). The family's range is their union.
MODULE, REMOTE_OPERATOR = 'module', 'remote_operator'
ADDRESS_RANGES: Dict[str, Tuple[int, int, str]] = {
    # Appendix B "Settings": "Address range 0 to 31" (section 3: set by the DIP switches); 0
    # is the Modbus broadcast address, which no starter answers.
    MODULE: (1, 31, 'the MCD Modbus Module DIP switches give 1-31 (manual 000 Appendix B: '
             '0 to 31, 0 is broadcast); a starter behind a Remote Operator takes 1-99: set '
             'mcd_interface: remote_operator'),
    # Section 11.8.2, par. 2 "RS485 network satellite address": 1 to 99 (AP ASCII or Modbus).
    REMOTE_OPERATOR: (1, 99, 'the Remote Operator par. 2 gives 1-99 (manual 000 section '
                      '11.8.2)'),
}
ADDRESS_RANGE = (1, 99)
INTERFACE = Setting(
    'mcd_interface', str, 'auto',
    'mcd: what sets the address: module = the MCD Modbus Module DIP switches (1-31), '
    'remote_operator = the Remote Operator, par. 2 (1-99); auto = remote_operator for an '
    'mcd3000 (it has no Modbus Module) or a model not named (model auto), module for the '
    'others',
    choices=('auto', MODULE, REMOTE_OPERATOR))


def address_range(model: str, options: Mapping[str, Any]) -> Tuple[int, int, str]:
    """Return (low, high, what sets it, in words) of the addresses an MCD ``model`` may have."""
    interface = options.get(INTERFACE.name, 'auto')
    if interface == 'auto':  # a model not named may be an MCD 3000: the wider range
        interface = REMOTE_OPERATOR if model in ('mcd3000', 'auto') else MODULE
    return ADDRESS_RANGES[interface]


@dataclass(frozen=True)
class Register:
    """One entry of the register map (section 6, "Modbus Register")."""

    number: int
    name: str
    access: str  # 'write', 'read', 'read_write'
    section: str = '6. Modbus Register'

    @property
    def address(self) -> int:
        """Return the address in the frame (the manual's number - 1)."""
        return self.number - 40001


REGISTERS: Tuple[Register, ...] = (
    Register(40002, 'command', 'write'),
    Register(40003, 'starter_status', 'read'),
    Register(40004, 'trip_code', 'read'),
    Register(40005, 'motor_current', 'read'),
    Register(40006, 'motor_temperature', 'read'),
    Register(40007, 'product_type_and_version', 'read'),
    Register(40008, 'serial_protocol_version', 'read'),
    Register(40009, 'first_parameter', 'read_write'),
)
REGISTER = {register.name: register for register in REGISTERS}
FIRST_PARAMETER_NUMBER = 40009
LAST_STATUS_NUMBER = 40008  # a read across 40008/40009 gives error 05 (section 8)
MAX_READ_REGISTERS = 125  # section 8: "up to a maximum of 125 register blocks"

# Section 6, register 40002: command values.
COMMAND_VALUES: Dict[Command, int] = {
    Command.START: 1,
    Command.STOP: 2,
    Command.RESET: 3,
    Command.QUICK_STOP: 4,  # coast to stop
    Command.FORCED_COMMS_TRIP: 5,
}

# Section 6, register 40003 bits 0-3: starter state -> the ROS contract's state names.
STATE_CODES: Dict[int, str] = {
    1: 'ready',
    2: 'starting',
    3: 'running',
    4: 'stopping',  # including braking
    5: 'restart_delay',  # including temperature check
    6: 'tripped',
    7: 'program_mode',
    8: 'jog_forward',
    9: 'jog_reverse',
}

# Section 6, register 40003 bits 4-6.
STATUS_BIT_PHASE_SEQUENCE = 4  # 1 = positive phase sequence (only valid if bit 6 = 1)
STATUS_BIT_CURRENT_ABOVE_FLC = 5
STATUS_BIT_INITIALISED = 6

# Section 6, register 40007 bits 3-7: product type.
PRODUCT_TYPES: Dict[int, str] = {1: 'MCD 3000', 4: 'MCD 200', 7: 'MCD 500'}

# Section 7, "Trip Codes": code -> (name, models that list it). 255 = no trip.
NO_TRIP = 255
_ALL = frozenset({'mcd201', 'mcd202', 'mcd500', 'mcd3000'})
_NOT_201 = frozenset({'mcd202', 'mcd500', 'mcd3000'})
_500_3000 = frozenset({'mcd500', 'mcd3000'})
_500 = frozenset({'mcd500'})
TRIP_CODES: Dict[int, Tuple[str, FrozenSet[str]]] = {
    1: ('Excess start time', _NOT_201),
    2: ('Motor overload (thermal model)', _NOT_201),
    3: ('Motor thermistor', _NOT_201),
    4: ('Current imbalance', _NOT_201),
    5: ('Frequency (mains supply)', _ALL),
    6: ('Phase sequence', _NOT_201),
    7: ('Instantaneous overcurrent', _500_3000),
    8: ('Power loss (power circuit)', _ALL),
    9: ('Undercurrent', _500_3000),
    10: ('Heatsink overtemperature', _500_3000),
    11: ('Motor connection', _500_3000),
    12: ('Input A trip (auxiliary input A)', _500),
    13: ('FLC too high (FLC out of range)', _500_3000),
    14: ('Unsupported option (not available in 6-wire)', _500),
    15: ('Starter communication', _ALL),
    16: ('Network communication', _ALL),
    17: ('Internal fault', _500),
    23: ('EEPROM fail', _500),
    26: ('L1 phase loss', _500),
    27: ('L2 phase loss', _500),
    28: ('L3 phase loss', _500),
    29: ('L1-T1 shorted', _500),
    30: ('L2-T2 shorted', _500),
    31: ('L3-T3 shorted', _500),
    33: ('Time-overcurrent (bypass overload)', frozenset({'mcd202', 'mcd500'})),
    35: ('Battery/clock', _500),
    36: ('Thermistor circuit', _500),
}

# Section 9, "Modbus Error Codes" (the module's own codes, partly unlike the Modbus spec):
# code -> (manual's description, what a technician should check).
MODULE_ERRORS: Dict[int, Tuple[str, str]] = {
    1: ('illegal function code',
        'the module supports only functions 03 (read) and 06 (write single register)'),
    2: ('illegal data address',
        'register number invalid for this starter (MCD 200 reads only 40003-40008)'),
    3: ('not readable data', 'the register cannot be read (40002 is write-only)'),
    4: ('not writable data', 'the register cannot be written (40003-40008 are read-only)'),
    5: ('data boundary fault',
        'read across the 40008/40009 boundary or more than 125 registers'),
    6: ('invalid command code', 'command register 40002 takes only 1-5'),
    7: ('illegal parameter read', 'invalid parameter number for this starter'),
    8: ('illegal parameter write', 'invalid parameter number, read-only or hidden parameter'),
    9: ('unsupported command',
        'network control disabled (Hand On mode or par. 3-2); '
        'set the starter to Auto On and par. 3-2 Comms in Remote to enable'),
    10: ('local communication error',
         'no communication between the Modbus Module and the starter: check the module '
         'is seated and the starter has control power'),
}


@dataclass(frozen=True)
class ModelFeatures:
    """What one model reports (sections 6 and 7: the per-model columns)."""

    name: str
    product_type: int
    states: FrozenSet[int]
    status_bits: FrozenSet[int]
    has_current: bool
    has_temperature: bool
    max_parameter: int  # 0: no parameter registers; MCD 500 up to 40599, MCD 3000 par. 60


_BASIC_STATES = frozenset({1, 2, 3, 4, 6})
MODEL_FEATURES: Dict[str, ModelFeatures] = {
    'mcd201': ModelFeatures('mcd201', 4, _BASIC_STATES, frozenset(), False, False, 0),
    'mcd202': ModelFeatures(
        'mcd202', 4, _BASIC_STATES,
        frozenset({STATUS_BIT_CURRENT_ABOVE_FLC, STATUS_BIT_INITIALISED}), True, True, 0),
    'mcd500': ModelFeatures(
        'mcd500', 7, frozenset(range(1, 10)),
        frozenset({STATUS_BIT_CURRENT_ABOVE_FLC, STATUS_BIT_INITIALISED}), True, True, 591),
    'mcd3000': ModelFeatures(
        'mcd3000', 1, frozenset({1, 2, 3, 4, 5, 6, 7}),
        frozenset({STATUS_BIT_INITIALISED}), True, True, 60),
}
# The product type cannot tell an MCD 201 from a 202: `auto` uses the 202's feature set.
AUTO_MODEL_BY_PRODUCT_TYPE = {1: 'mcd3000', 4: 'mcd202', 7: 'mcd500'}


def trip_name(code: int, model: str = '') -> str:
    """Return the manual's name of trip ``code`` ('' for no trip)."""
    if code in (0, NO_TRIP):
        return ''
    entry = TRIP_CODES.get(code)
    if entry is None:
        return f'unknown trip code {code}'
    name, models = entry
    if model and model not in models:
        return f'{name} (not listed for {model})'
    return name


def module_error_text(code: int) -> str:
    """Return technician text for one of the module's error codes 01-10."""
    entry = MODULE_ERRORS.get(code)
    if entry is None:
        return f'Modbus error {code:02d} (not in the module manual)'
    description, advice = entry
    return f'{advice} ({description}), Modbus error {code:02d}'


def decode_product_word(word: int) -> Tuple[int, int]:
    """Split register 40007 into (product type, parameter list version)."""
    return bits(word, 3, 7), bits(word, 0, 2)


def resolve_model(configured: str, product_word: int) -> str:
    """
    Return the model to use for a device reporting ``product_word`` in 40007.

    Raises ModelMismatch when the configured model is not the product the device reports.
    """
    product_type, _ = decode_product_word(product_word)
    reported = PRODUCT_TYPES.get(product_type, f'unknown product type {product_type}')
    if configured == 'auto':
        model = AUTO_MODEL_BY_PRODUCT_TYPE.get(product_type)
        if model is None:
            raise ModelMismatch(
                f'device reports {reported} in register 40007 (value {product_word}); '
                'set model explicitly if this is an MCD starter')
        return model
    expected = MODEL_FEATURES[configured].product_type
    if product_type != expected:
        raise ModelMismatch(
            f'model mismatch: configured {configured} but the device reports {reported} '
            f'(register 40007 = {product_word}); fix the model parameter or the address')
    return configured


class McdProfile(DeviceProfile, ParameterAccess):
    """Register map, decode and commands of one MCD starter on Modbus RTU."""

    family = FAMILY
    commands = frozenset(COMMAND_VALUES)

    def __init__(self, model: str = 'auto', current_scale: float = 1.0,
                 slow_readouts: Optional[SlowReadouts] = None):
        if model not in MODELS:
            raise ConfigError(f'unknown MCD model {model!r}: allowed {", ".join(MODELS)}')
        super().__init__(model)
        self.current_scale = current_scale
        self.slow_readouts = slow_readouts or SlowReadouts(0.0)
        self._product_registers: Optional[List[int]] = None  # 40007-40008 as last read

    @property
    def features(self) -> ModelFeatures:
        """Return the features of the resolved (or configured) model."""
        return MODEL_FEATURES[self.resolved_model or 'mcd202']

    @property
    def reading_fields(self) -> FrozenSet[str]:
        """Return current and temperature unless the model is an MCD 201."""
        if self.resolved_model == 'mcd201':
            return frozenset()
        return frozenset({'motor_current', 'motor_temperature'})

    def poll(self, control: ControlView, now_s: float) -> PollCycle:
        """
        Read 40003-40006 (status, trip, current, temperature) in one transaction.

        The product and protocol registers 40007-40008 come with them when the slow readouts
        are due and until the model is known (never past 40008: section 8, error 05).
        """
        first = REGISTER['starter_status']
        slow = self.slow_readouts.due(now_s) or self._product_registers is None
        last = LAST_STATUS_NUMBER if slow else REGISTER['motor_temperature'].number
        registers = yield PollStep(ReadRegisters(first.address, last - first.number + 1),
                                   stamps=True)
        return self.decode([registers])

    def decode(self, blocks: List[List[int]]) -> DeviceReading:
        """Decode the registers of one poll (40003-40008, or 40003-40006) into a reading."""
        registers = blocks[0]
        if len(registers) == 6:
            self._product_registers = registers[4:]
        elif len(registers) != 4 or self._product_registers is None:
            raise ProtocolError(f'expected 6 registers 40003-40008 (or 4 once the model is '
                                f'known), got {len(registers)}')
        status_word, trip_raw, current_raw, temperature_raw = registers[:4]
        product_word, protocol = self._product_registers
        self.resolved_model = resolve_model(self.configured_model, product_word)
        features = self.features
        trip_code = 0 if trip_raw == NO_TRIP else trip_raw
        reading = starter_reading(features, status_word, trip_code,
                                  trip_name(trip_code, features.name), 'in 40003')
        if features.has_current:
            reading.motor_current_a = float(current_raw) * self.current_scale
        if features.has_temperature:
            reading.motor_temperature_pct = float(temperature_raw)
        product_type, list_version = decode_product_word(product_word)
        reading.details.update({
            'positive_phase_sequence': str(bit(status_word, STATUS_BIT_PHASE_SEQUENCE)),
            'trip_code_register': str(trip_raw),
            'product_type': PRODUCT_TYPES.get(product_type, str(product_type)),
            'parameter_list_version': str(list_version),
            'serial_protocol_version': str(protocol),
        })
        return reading

    def on_offline(self) -> None:
        """Forget the product registers: the device may come back as another one."""
        self._product_registers = None

    def command_plan(self, command: Command, control: ControlView) -> CommandPlan:
        """Return the write that carries out ``command`` (register 40002)."""
        value = COMMAND_VALUES.get(command)
        if value is None:
            raise CommandRefused(f'MCD starters have no {command.value} command (allowed: '
                                 f'{", ".join(sorted(c.value for c in COMMAND_VALUES))})')
        return CommandPlan(command, (WriteRegister(REGISTER['command'].address, value),))

    def parameter_address(self, number: int) -> int:
        """Return the frame address of parameter ``number`` (1 = register 40009)."""
        maximum = self.features.max_parameter
        if maximum == 0:
            raise CommandRefused(
                f'{self.features.name} has no parameter registers over Modbus '
                '(MCD 200: only 40003-40008)')
        if not 1 <= number <= maximum:
            raise CommandRefused(
                f'parameter {number} is out of range for {self.features.name}: 1-{maximum}')
        return FIRST_PARAMETER_NUMBER + number - 1 - 40001

    def parameter_plan(self, number: int, value: Any = None,
                       options: ParameterOptions = ParameterOptions()) -> ParameterPlan:
        """Return the read (value None) or write of parameter ``number`` (16-bit raw)."""
        if options.data_type not in (None, 'uint16') or options.conversion not in (None, 0) \
                or options.index is not None or options.eeprom:
            raise CommandRefused('MCD parameters are raw 16-bit registers: data type, '
                                 'conversion, index and EEPROM options do not apply')
        address = self.parameter_address(number)
        if value is None:
            return ParameterPlan(f'parameter {number} read', (ReadRegisters(address, 1),),
                                 lambda results: results[0][0])
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= 0xFFFF:
            raise CommandRefused(f'value {value!r} does not fit a 16-bit register')
        return ParameterPlan(f'parameter {number} write', (WriteRegister(address, value),),
                             lambda results: f'parameter {number} = {value} acknowledged')

    def parameter_numbers(self) -> Sequence[int]:
        """Return every parameter number of the model (1 to its last)."""
        return range(1, self.features.max_parameter + 1)

    def explain_exception(self, code: int, detail: Optional[int] = None) -> str:
        """Return technician text for a Modbus exception code from the module."""
        return module_error_text(code)


def starter_reading(features: ModelFeatures, status_word: int, trip_code: int,
                    trip_text: str, where: str) -> DeviceReading:
    """
    Return the reading of an MCD status word, the same over Modbus (40003) and AP ASCII (C22).

    ``trip_code`` is already the contract's (0 = no trip); ``where`` names the source of the
    status for the warning about an unknown state code.
    """
    state_code = bits(status_word, 0, 3)
    state = STATE_CODES.get(state_code, 'unknown')
    reading = DeviceReading(state=state, status_word=status_word, trip_code=trip_code,
                            trip_name=trip_text)
    reading.details = {
        'model': features.name,
        'state_code': str(state_code),
        'initialised': str(bit(status_word, STATUS_BIT_INITIALISED)),
        'current_above_flc': str(bit(status_word, STATUS_BIT_CURRENT_ABOVE_FLC)),
    }
    if state == 'unknown':
        reading.warnings.append(f'unknown state code {state_code} {where}')
    if bit(status_word, STATUS_BIT_CURRENT_ABOVE_FLC) and \
            STATUS_BIT_CURRENT_ABOVE_FLC in features.status_bits:
        reading.warnings.append('motor current exceeds FLC')
    if state == 'tripped':
        if not trip_code:
            reading.trip_code = TRIP_CODE_UNKNOWN
            reading.trip_name = reading.trip_name or 'tripped (no trip code reported)'
        reading.fault = f'tripped: {reading.trip_name}'
    return reading


def make_profile(model: str, protocol: str, options: Mapping[str, Any]) -> McdProfile:
    """Return the profile of an MCD starter on ``protocol`` (Modbus or AP ASCII)."""
    scale = options.get('current_scale', 1.0)
    slow = SlowReadouts(options.get('readout_period', 0.0))
    if protocol == 'ap_ascii':
        from drive_bridge.devices.mcd_ascii import McdAsciiProfile
        return McdAsciiProfile(model, scale, slow)
    return McdProfile(model, scale, slow)


ENTRY = Family(
    name=FAMILY,
    description='MCD 201/202/500 via the MCD Modbus Module, MCD 3000 via the Remote Operator',
    models=MODELS, address_range=ADDRESS_RANGE,
    protocols=('modbus_rtu', 'modbus_tcp', 'rtu_over_tcp', 'ap_ascii'), settings=(INTERFACE,),
    make_profile=make_profile, model_address_range=address_range)
