"""
Behaviour model of an MCD soft starter behind the MCD Modbus Module, with explicit time.

Pure: no I/O and no clock of its own; every call takes ``now_s``. The register map, error
codes and per-model features are the device profile's tables
(:mod:`drive_bridge.devices.mcd`), so the simulator and the driver read one source.
"""

from collections import deque
from dataclasses import dataclass, field
import math
from typing import Deque, Dict, List, Optional

from drive_bridge.devices import mcd

READY, STARTING, RUNNING, STOPPING, RESTART_DELAY, TRIPPED = 1, 2, 3, 4, 5, 6
THERMAL_TRIP_PCT = 105.0  # manual section 10.3: "Trip point is 0105%"
MOTOR_OVERLOAD_TRIP = 2
NETWORK_COMMUNICATION_TRIP = 16


class ModuleError(Exception):
    """The module answers with one of its error codes 01-10 (manual section 9)."""

    def __init__(self, code: int):
        super().__init__(mcd.module_error_text(code))
        self.code = code


@dataclass
class McdSimConfig:
    """Settings of one simulated starter; times in seconds, currents in amperes."""

    model: str = 'mcd500'
    motor_flc_a: float = 100.0  # manual example: par. 1-1 Motor FLC = 100 A
    current_limit_pct: float = 350.0
    run_current_pct: float = 80.0
    start_time_s: float = 3.0
    stop_time_s: float = 2.0
    restart_delay_s: float = 0.0
    thermal_time_constant_s: float = 300.0
    current_register_scale: float = 1.0  # MCD5-0068B and smaller report 10x: 10.0
    parameter_list_version: int = 1
    serial_protocol_version: int = 1
    parameter_count: Optional[int] = None  # default: the model's maximum
    parameters: Dict[int, int] = field(default_factory=lambda: {1: 100, 4: 350})


class McdModel:
    """One MCD starter and its Modbus Module, as the manual describes them."""

    def __init__(self, config: Optional[McdSimConfig] = None, now_s: float = 0.0):
        self.config = config or McdSimConfig()
        if self.config.model not in mcd.MODEL_FEATURES:
            raise ValueError(f'unknown MCD model {self.config.model!r}')
        self.features = mcd.MODEL_FEATURES[self.config.model]
        count = self.config.parameter_count
        self.parameter_count = self.features.max_parameter if count is None else count
        self.parameters: Dict[int, int] = {
            number: value for number, value in self.config.parameters.items()
            if 1 <= number <= self.parameter_count}
        self.state = READY
        self.state_since_s = now_s
        self.now_s = now_s
        self.trip_code = mcd.NO_TRIP
        self.motor_current_a = 0.0
        self.temperature_pct = 0.0
        self.hand_on = False
        self.comms_in_remote_disabled = False
        self.local_comms_error = False
        self.commands_received: Deque[int] = deque(maxlen=1000)

    # -- time ---------------------------------------------------------------------------
    def advance(self, now_s: float) -> None:
        """Advance the model to ``now_s``: state timing, current and thermal model."""
        dt = max(0.0, now_s - self.now_s)
        self.now_s = now_s
        elapsed = now_s - self.state_since_s
        if self.state == STARTING and elapsed >= self.config.start_time_s:
            self._enter(RUNNING, self.state_since_s + self.config.start_time_s)
        elif self.state == STOPPING and elapsed >= self.config.stop_time_s:
            self._after_stop(self.state_since_s + self.config.stop_time_s)
        elif self.state == RESTART_DELAY and elapsed >= self.config.restart_delay_s:
            self._enter(READY, self.state_since_s + self.config.restart_delay_s)
        self.motor_current_a = self._current_now()
        self._heat(dt)

    def _enter(self, state: int, since_s: float) -> None:
        self.state = state
        self.state_since_s = since_s

    def _after_stop(self, at_s: float) -> None:
        if self.config.restart_delay_s > 0 and 5 in self.features.states:
            self._enter(RESTART_DELAY, at_s)
        else:
            self._enter(READY, at_s)

    def _current_now(self) -> float:
        flc = self.config.motor_flc_a
        run = flc * self.config.run_current_pct / 100.0
        elapsed = self.now_s - self.state_since_s
        if self.state == STARTING:
            limit = flc * self.config.current_limit_pct / 100.0
            start = self.config.start_time_s
            rise_s = min(0.4, 0.2 * start)
            if elapsed < rise_s:
                return limit * elapsed / rise_s
            if elapsed < 0.7 * start:
                return limit
            fraction = min(1.0, (elapsed - 0.7 * start) / (0.3 * start))
            return limit + (run - limit) * fraction
        if self.state == RUNNING:
            return run * (1.0 + 0.01 * math.sin(self.now_s))
        if self.state == STOPPING:
            fraction = min(1.0, elapsed / self.config.stop_time_s)
            return run * (1.0 - 0.7 * fraction)
        return 0.0

    def _heat(self, dt: float) -> None:
        """First-order thermal model: % of motor thermal capacity towards 100 * (I/FLC)^2."""
        if dt <= 0:
            return
        ratio = self.motor_current_a / self.config.motor_flc_a
        target = 100.0 * ratio * ratio
        alpha = 1.0 - math.exp(-dt / self.config.thermal_time_constant_s)
        self.temperature_pct += (target - self.temperature_pct) * alpha
        if self.temperature_pct >= THERMAL_TRIP_PCT and self.state in (STARTING, RUNNING):
            self.trip(MOTOR_OVERLOAD_TRIP, self.now_s)

    # -- faults -------------------------------------------------------------------------
    def trip(self, code: int, now_s: float) -> None:
        """Trip the starter with ``code`` (trip table, manual section 7)."""
        self.advance(now_s)
        self.trip_code = code
        self._enter(TRIPPED, now_s)
        self.motor_current_a = 0.0

    # -- Modbus registers ---------------------------------------------------------------
    def status_word(self) -> int:
        """Return register 40003 as the module reports it for this model."""
        word = self.state & 0x0F
        flc = self.config.motor_flc_a
        if mcd.STATUS_BIT_CURRENT_ABOVE_FLC in self.features.status_bits and \
                self.motor_current_a > flc:
            word |= 1 << mcd.STATUS_BIT_CURRENT_ABOVE_FLC
        if mcd.STATUS_BIT_INITIALISED in self.features.status_bits:
            word |= 1 << mcd.STATUS_BIT_INITIALISED
        return word

    def read_registers(self, address: int, count: int, now_s: float) -> List[int]:
        """Answer a function 03 read of ``count`` registers at frame ``address``."""
        self.advance(now_s)
        if self.local_comms_error:
            raise ModuleError(10)
        first = address + 40001
        last = first + count - 1
        if count < 1 or count > mcd.MAX_READ_REGISTERS:
            raise ModuleError(5)
        if first <= 40002:
            raise ModuleError(3 if first == 40002 else 2)
        if first <= mcd.LAST_STATUS_NUMBER:
            if last > mcd.LAST_STATUS_NUMBER:
                raise ModuleError(5)
            status = self._status_registers()
            return status[first - 40003:last - 40003 + 1]
        return self._read_parameters(first - mcd.FIRST_PARAMETER_NUMBER + 1, count)

    def _status_registers(self) -> List[int]:
        current_raw = int(round(self.motor_current_a * self.config.current_register_scale))
        product = (self.features.product_type << 3) | (self.config.parameter_list_version & 7)
        return [
            self.status_word(),
            self.trip_code,
            current_raw if self.features.has_current else 0,
            int(round(self.temperature_pct)) if self.features.has_temperature else 0,
            product,
            self.config.serial_protocol_version,
        ]

    def _read_parameters(self, first_number: int, count: int) -> List[int]:
        if self.parameter_count == 0:
            raise ModuleError(2)
        if first_number + count - 1 > self.parameter_count:
            raise ModuleError(7)
        return [self.parameters.get(n, 0) for n in range(first_number, first_number + count)]

    def write_register(self, address: int, value: int, now_s: float) -> None:
        """Carry out a function 06 write of ``value`` at frame ``address``."""
        self.advance(now_s)
        if self.local_comms_error:
            raise ModuleError(10)
        number = address + 40001
        if number == 40002:
            self._command(value, now_s)
        elif 40003 <= number <= mcd.LAST_STATUS_NUMBER:
            raise ModuleError(4)
        elif number >= mcd.FIRST_PARAMETER_NUMBER and self.parameter_count:
            parameter = number - mcd.FIRST_PARAMETER_NUMBER + 1
            if parameter > self.parameter_count:
                raise ModuleError(8)
            self.parameters[parameter] = value
        else:
            raise ModuleError(2)

    def _command(self, value: int, now_s: float) -> None:
        if value not in (1, 2, 3, 4, 5):
            raise ModuleError(6)
        if value in (1, 2, 4) and (self.hand_on or self.comms_in_remote_disabled):
            raise ModuleError(9)
        self.commands_received.append(value)
        if value == 1 and self.state == READY:
            self._enter(STARTING, now_s)
        elif value == 2 and self.state in (STARTING, RUNNING):
            self._enter(STOPPING, now_s)
        elif value == 3 and self.state == TRIPPED:
            self.trip_code = mcd.NO_TRIP
            self._enter(READY, now_s)
        elif value == 4 and self.state in (STARTING, RUNNING, STOPPING):
            self._enter(READY, now_s)
        elif value == 5:
            self.trip(NETWORK_COMMUNICATION_TRIP, now_s)
        self.motor_current_a = self._current_now()
