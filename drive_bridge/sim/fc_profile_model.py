"""
Behaviour model of an FC-profile drive, with explicit time. Pure.

Two variants share it: the VLT Micro Drive FC 51 (``family='fc'``) and a VLT 5000/6000 behind
the Modbus RTU option card (``family='vlt'``); they differ in their parameter tables, the
readout numbers and where the comms timeout is set (FC: par. 8-03/8-04; option card:
register 2, 10 ms units, after which the simulated drive ramp-stops).

It follows the FC control profile of manual 004 section 5.6: the control word is obeyed only
with bit 10 (data valid) set and only under bus control (status word bit 9); the output
ramps towards the bus reference per par. 3-41/3-42 (quick stop: 3-81); coasting drops the
output at once; reset acts on the rising edge of bit 7. The control word timeout (par.
8-03/8-04) stops or trips the drive when the master stops writing. Alarms are injectable.
"""

from collections import deque
from dataclasses import dataclass, field
import math
from typing import Deque, Dict, Optional

from drive_bridge.devices import fc51, fc51_parameters, vlt
from drive_bridge.devices.parameters import ParameterSpec
from drive_bridge.protocol import fc_profile as ctl, fc_profile_scaling
from drive_bridge.sim.fc_profile_parameter_store import FcProfileParameterStore

# Alarm word bits (manual 004 section 7.1.1).
ALARM_CONTROL_WORD_TIMEOUT = 4
ALARM_OVER_CURRENT = 5
# Par. 8-04 control word timeout functions (protocols.md, FC 102 list).
TIMEOUT_OFF, TIMEOUT_FREEZE, TIMEOUT_STOP, TIMEOUT_JOG, TIMEOUT_MAX, TIMEOUT_TRIP = range(6)
# A VLT parameter outside the bridge's table, so that reading one with --type and
# --conversion can be shown and tested: par. 205 Maximum Reference (MG.90.D1.02 "Size
# attribute": a reference in Hz with conversion index -3; int32 as the VLT 5000 list has it).
VLT_BEYOND_TABLE = ParameterSpec(205, 'Maximum Reference', 'int32', -3, setting=None)
VLT_MAXIMUM_REFERENCE_RAW = 50000  # 50.000 Hz
# Motor current readout of each VLT model (the other model's number is no parameter there).
VLT_CURRENT_PARAMETER = {'vlt5000': 520, 'vlt6000': 514}


@dataclass
class FcProfileSimConfig:
    """Settings of one simulated drive; times in seconds, currents in amperes."""

    model: str = 'fc51'  # fc51, vlt5000 or vlt6000
    type_text: str = 'FC-051PK75T4E20H3BXCXXXSXXXX'
    software_version: str = '2.70'
    motor_frequency_hz: float = 50.0  # par. 1-23, = 100 % reference
    motor_current_a: float = 2.0  # par. 1-24
    no_load_current_pct: float = 30.0
    load_pct: float = 60.0  # load torque, % of nominal
    ramp_up_s: float = 3.0  # par. 3-41
    ramp_down_s: float = 3.0  # par. 3-42
    quick_stop_ramp_s: float = 0.5  # par. 3-81
    ctw_timeout_s: float = 1.0  # par. 8-03
    ctw_timeout_function: int = TIMEOUT_OFF  # par. 8-04
    thermal_time_constant_s: float = 120.0
    extra_parameters: Dict[int, int] = field(default_factory=dict)
    # The line the simulator serves it on; the FC 51 reports them as par. 8-30..8-33.
    address: int = 1
    protocol: str = 'modbus_rtu'  # or fc_protocol
    baudrate: int = 9600
    parity: str = 'E'
    stopbits: int = 1


class FcProfileModel:
    """
    One FC-profile drive: control word, ramps, comms timeout, current, heat and alarms.

    Its parameters are a :class:`FcProfileParameterStore` (``parameters`` is the store's dict of
    raw values by number, ``table`` its parameter table); the live readouts come from here.
    """

    def __init__(self, config: Optional[FcProfileSimConfig] = None, now_s: float = 0.0):
        self.config = config or FcProfileSimConfig()
        self.family = 'vlt' if self.config.model.startswith('vlt') else 'fc'
        self.store = parameter_store(self.config, self.family)
        self.table = self.store.table
        self.parameters = self.store.values  # by number, raw units (the store's own dict)
        self.now_s = now_s
        self.control_word = 0  # last control word received (0 = not yet)
        self.reference_word = 0
        self.output_pct = 0.0  # signed, % of motor frequency
        self.alarm_word = 0
        self.trip_locked = False
        self.local_mode = False
        self.temperature_pct = 0.0
        self.eeprom_writes = False
        self.last_control_write_s: Optional[float] = None
        self.timeout_active = False
        self.last_error = 0
        self.control_words_received: Deque[int] = deque(maxlen=1000)  # the latest
        self.card_timeouts = [0, 0]  # option card registers 2 and 3, 10 ms units

    # -- time ---------------------------------------------------------------------------
    @property
    def tripped(self) -> bool:
        """Return whether an alarm holds the drive tripped."""
        return self.alarm_word != 0

    def run_requested(self) -> bool:
        """Return whether the last control word asks to run and the drive may."""
        return (not self.tripped and not self.local_mode
                and ctl.is_start(self.control_word))

    def target_pct(self) -> float:
        """Return where the output is heading: the reference while running, else 0."""
        if self.timeout_active and self.timeout_function() == TIMEOUT_FREEZE:
            return self.output_pct
        if self.timeout_active and self.timeout_function() == TIMEOUT_MAX:
            return 100.0
        if not self.run_requested() or self._stop_by_timeout():
            return 0.0
        return fc_profile_scaling.word_to_percent(self.reference_word)

    def _stop_by_timeout(self) -> bool:
        return self.timeout_active and self.timeout_function() in (TIMEOUT_STOP, TIMEOUT_TRIP)

    def timeout_function(self) -> int:
        """Return what a comms timeout does (FC: par. 8-04; option card: stop)."""
        if self.family == 'vlt':
            return TIMEOUT_STOP if self.card_timeouts[0] else TIMEOUT_OFF
        return self.parameters[804]

    def timeout_s(self) -> float:
        """Return the comms timeout (FC: par. 8-03 in 0.1 s; option card: register 2)."""
        if self.family == 'vlt':
            return self.card_timeouts[0] / 100.0
        return self.parameters[803] / 10.0

    def advance(self, now_s: float) -> None:
        """Advance ramps, control word timeout, current and temperature to ``now_s``."""
        dt = max(0.0, now_s - self.now_s)
        self.now_s = now_s
        self._check_timeout(now_s)
        coast = self._data_valid() and not self.control_word & (1 << ctl.CTW_COAST_OFF)
        if self.tripped or coast:
            self.output_pct = 0.0  # the output is switched off at once: the motor coasts
        else:
            self._ramp(dt)
        self._heat(dt)

    def _data_valid(self) -> bool:
        return bool(self.control_word & (1 << ctl.CTW_DATA_VALID))

    def _ramp(self, dt: float) -> None:
        target = self.target_pct()
        quick = self._data_valid() and not self.control_word & (1 << ctl.CTW_QUICK_STOP_OFF)
        speeding_up = abs(target) > abs(self.output_pct) and target * self.output_pct >= 0
        ramp_s = self.parameters[381 if quick else 341 if speeding_up else 342] / 100.0
        step = 100.0 * dt / max(ramp_s, 0.01)
        if abs(target - self.output_pct) <= step:
            self.output_pct = target
        else:
            self.output_pct += math.copysign(step, target - self.output_pct)

    def _check_timeout(self, now_s: float) -> None:
        function = self.timeout_function()
        timeout_s = self.timeout_s()
        if function == TIMEOUT_OFF or self.last_control_write_s is None or \
                now_s - self.last_control_write_s < timeout_s:
            return
        if not self.timeout_active:
            self.timeout_active = True
            if function == TIMEOUT_TRIP:
                self.trip(ALARM_CONTROL_WORD_TIMEOUT, now_s)

    def _heat(self, dt: float) -> None:
        if dt <= 0:
            return
        ratio = self.motor_current_a() / self.config.motor_current_a
        alpha = 1.0 - math.exp(-dt / self.config.thermal_time_constant_s)
        self.temperature_pct += (100.0 * ratio * ratio - self.temperature_pct) * alpha

    def motor_current_a(self) -> float:
        """Return the motor current: magnetising part plus load, only while the output runs."""
        if self.output_pct == 0.0:
            return 0.0
        config = self.config
        load = config.no_load_current_pct + (100.0 - config.no_load_current_pct) * \
            config.load_pct / 100.0 * min(1.0, abs(self.output_pct) / 100.0)
        ramping = 15.0 if self.output_pct != self.target_pct() else 0.0
        return config.motor_current_a * (load + ramping) / 100.0

    # -- faults -------------------------------------------------------------------------
    def trip(self, alarm_bit: int, now_s: float, locked: bool = False) -> None:
        """Raise the alarm of ``alarm_bit`` (16-90 bit): the drive trips and coasts."""
        self.now_s = max(self.now_s, now_s)
        self.alarm_word |= 1 << alarm_bit
        self.trip_locked = self.trip_locked or locked
        self.output_pct = 0.0

    # -- process data -------------------------------------------------------------------
    def write_control(self, control_word: int, reference_word: int, now_s: float) -> None:
        """Take control word and reference from the bus (coils 1-32 or registers)."""
        self.advance(now_s)
        self.last_control_write_s = now_s
        self.timeout_active = False
        self.control_words_received.append(control_word)
        if self.local_mode or not control_word & (1 << ctl.CTW_DATA_VALID):
            return  # local operation, or "data not valid": the drive ignores the word
        rising_reset = control_word & (1 << ctl.CTW_RESET) and \
            not self.control_word & (1 << ctl.CTW_RESET)
        self.control_word = control_word
        self.reference_word = reference_word & 0xFFFF
        if rising_reset and not self.trip_locked:
            self.alarm_word = 0
        self.advance(now_s)  # a coast takes effect at once

    def warning_word(self) -> int:
        """Return par. 16-92."""
        word = 0
        if self.timeout_active:
            word |= 1 << ALARM_CONTROL_WORD_TIMEOUT
        if self.motor_current_a() > 1.5 * self.config.motor_current_a:
            word |= 1 << ALARM_OVER_CURRENT
        return word

    def status_word(self) -> int:
        """
        Return the FC-profile status word (manual 004 sections 5.6.3 and 5.6.4).

        Bit 11 *Running* is 1 when "the frequency converter has a start signal or ... the
        output frequency is higher than 0 Hz", and bit 8 *Speed = reference* when "the
        present motor speed matches the preset speed reference": a drive started with a 0 %
        reference sets both at 0 Hz, so it reads running, not ready. The VLT option card
        manual (003) does not describe the status bits; the VLT variant follows the same FC
        profile.
        """
        bits = {
            ctl.STW_CONTROL_READY: not self.tripped,
            ctl.STW_UNIT_READY: True,
            ctl.STW_ENABLED: bool(self.control_word & (1 << ctl.CTW_COAST_OFF)),
            ctl.STW_TRIP: self.tripped and not self.trip_locked,
            ctl.STW_TRIP_LOCKED: self.trip_locked,
            ctl.STW_WARNING: self.warning_word() != 0,
            ctl.STW_ON_REFERENCE: self.output_pct == self.target_pct(),
            ctl.STW_BUS_CONTROL: not self.local_mode,
            ctl.STW_FREQUENCY_OK: True,
            ctl.STW_RUNNING: self.output_pct != 0.0 or self.run_requested(),
            ctl.STW_TORQUE_EXCEEDED: self.motor_current_a() > 1.5 * self.config.motor_current_a,
            ctl.STW_THERMAL_WARNING: self.temperature_pct > 100.0,
        }
        return sum(1 << index for index, value in bits.items() if value)

    def actual_word(self) -> int:
        """Return the main actual value (output frequency) in FC scaling."""
        return fc_profile_scaling.percent_to_word(max(-200.0, min(199.99, self.output_pct)))

    # -- parameters ---------------------------------------------------------------------
    @property
    def index(self) -> int:
        """Return the index register (FC: register 9; option card: IND, register 1)."""
        return self.store.index

    @index.setter
    def index(self, value: int) -> None:
        self.store.index = value

    def readout(self, number: int) -> Optional[object]:
        """Return the live value of a readout parameter (raw units), or None."""
        current_x100 = round(self.motor_current_a() * 100)
        if self.family == 'vlt':
            return {VLT_CURRENT_PARAMETER[self.config.model]: current_x100,
                    538: self.alarm_word, 540: self.warning_word(),
                    541: int(self.output_pct != self.target_pct()), 953: 0}.get(number)
        frequency_x10 = round(abs(self.output_pct) * self.config.motor_frequency_hz / 10.0)
        values = {
            1540: self.config.type_text, 1543: self.config.software_version,
            1600: self.control_word, 1602: round(fc_profile_scaling.word_to_percent(
                self.reference_word) * 10), 1603: self.status_word(),
            1613: frequency_x10, 1614: current_x100,
            1618: min(255, round(self.temperature_pct)),
            1690: self.alarm_word, 1692: self.warning_word(),
            1694: int(self.output_pct != self.target_pct()),
        }
        return values.get(number)

    def read_parameter(self, number: int, count: int, now_s: float) -> list:
        """Return ``count`` registers of parameter ``number``; raise ParameterError."""
        self.advance(now_s)
        return self.store.read(number, count, self.readout(number))

    def write_parameter(self, number: int, registers: list, now_s: float) -> None:
        """Store a parameter write; raise ParameterError with register 7's detail."""
        self.advance(now_s)
        self.store.write(number, registers, is_readout=self.readout(number) is not None,
                         running=self.output_pct != 0.0)


def parameter_store(config: FcProfileSimConfig, family: str) -> FcProfileParameterStore:
    """Return the parameters a drive of ``family`` starts with, its configuration's among them."""
    data = vlt.DATA if family == 'vlt' else fc51.DATA
    table: Dict[int, ParameterSpec] = dict(data.table(config.model))
    # The ramps live under the FC numbers 3-41, 3-42 and 3-81 in both variants.
    configured: Dict[int, object] = {
        341: round(config.ramp_up_s * 100), 342: round(config.ramp_down_s * 100),
        381: round(config.quick_stop_ramp_s * 100)}
    if family == 'vlt':
        table[VLT_BEYOND_TABLE.number] = VLT_BEYOND_TABLE
        configured.update({104: 50, VLT_BEYOND_TABLE.number: VLT_MAXIMUM_REFERENCE_RAW})
    else:
        configured.update({124: round(config.motor_current_a * 100),
                           803: round(config.ctw_timeout_s * 10),
                           804: config.ctw_timeout_function, 3: 0})
        configured.update(serial_line_parameters(config))
    return FcProfileParameterStore(table, data.conversion_factors, configured,
                                   config.extra_parameters,
                                   maxima={} if family == 'vlt' else {804: TIMEOUT_TRIP},
                                   option_card=family == 'vlt')


def serial_line_parameters(config: FcProfileSimConfig) -> Dict[int, object]:
    """Return par. 8-30..8-33 as the line the drive is served on (its address among them)."""
    def option(by_option: Dict[int, object], value: object, what: str) -> int:
        for number, meaning in by_option.items():
            if meaning == value:
                return number
        raise ValueError(f'the FC 51 has no par. 8-3x option for {what} {value!r}: allowed '
                         f'{", ".join(str(meaning) for meaning in by_option.values())}')
    return {830: option(fc51_parameters.PROTOCOL_BY_OPTION, config.protocol, 'protocol'),
            831: config.address,
            832: option(fc51_parameters.BAUD_BY_OPTION, config.baudrate, 'baud rate'),
            833: option(fc51_parameters.FRAMING_BY_OPTION, (config.parity, config.stopbits),
                        'parity and stop bits')}
