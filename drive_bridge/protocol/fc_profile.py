"""
The Danfoss FC control profile: control word (CTW) and status word (STW), pure.

Sources: FC 51 manual ``004_59cc2fa01c5c97de.txt`` sections 5.6.1-5.6.4 and the VLT
5000/6000 Modbus RTU option card manual ``003_be38f660678fad2b.txt`` ("FC Protocol Control
Word Bit Descriptions", stop precedence: coast, quick stop, DC brake, ramp stop).
The manuals' frames give the two anchor words: start 0x047C and ramp stop 0x043C.
"""

from dataclasses import dataclass
from typing import Dict, Optional

from drive_bridge.protocol.commands import Command
from drive_bridge.protocol.words import bit

# Control word bits (section 5.6.1): for bits 2-5 a 0 *requests* the stop or the freeze.
CTW_DC_BRAKE_OFF = 2  # 0 = DC brake
CTW_COAST_OFF = 3  # 0 = coast stop
CTW_QUICK_STOP_OFF = 4  # 0 = quick stop (ramp 3-81)
CTW_NO_FREEZE = 5  # 0 = freeze output
CTW_START = 6  # 0 = ramp stop, 1 = start
CTW_RESET = 7  # rising edge resets a trip
CTW_JOG = 8
CTW_RAMP_2 = 9
CTW_DATA_VALID = 10  # 0 = the drive ignores the control word
CTW_RELAY_1 = 11
CTW_REVERSE = 15

RAMP_STOP_WORD = 0x043C  # manual frame "ramp stop": bits 2, 3, 4, 5, 10
START_WORD = RAMP_STOP_WORD | (1 << CTW_START)  # 0x047C, manual frame "start at 40 %"

# The stop commands of the ROS contract, strongest first (option card manual: "The
# precedence of the stop commands is as follows: 1. Coast stop 2. Quick stop 3. DC Brake
# 4. Normal (Ramp) stop").
COMMAND_WORDS: Dict[Command, int] = {
    Command.START: START_WORD,
    Command.STOP: RAMP_STOP_WORD,
    Command.QUICK_STOP: RAMP_STOP_WORD & ~(1 << CTW_QUICK_STOP_OFF),  # 0x042C
    Command.COAST_STOP: RAMP_STOP_WORD & ~(1 << CTW_COAST_OFF),  # 0x0434
}


def with_reset(control_word: int) -> int:
    """Return ``control_word`` with the reset bit set (send it, then the word without it)."""
    return control_word | (1 << CTW_RESET)


def is_start(control_word: int) -> bool:
    """Return whether ``control_word`` asks the drive to run (start, data valid, no stop)."""
    needed = (1 << CTW_START) | (1 << CTW_DATA_VALID) | (1 << CTW_COAST_OFF) | \
        (1 << CTW_QUICK_STOP_OFF) | (1 << CTW_DC_BRAKE_OFF)
    return control_word & needed == needed


# Status word bits (section 5.6.3) -> name of the flag when the bit is 1.
STW_CONTROL_READY = 0
STW_UNIT_READY = 1
STW_ENABLED = 2  # 0 = coasting: the drive released the motor
STW_TRIP = 3
STW_ERROR_NO_TRIP = 4
STW_TRIP_LOCKED = 6
STW_WARNING = 7
STW_ON_REFERENCE = 8
STW_BUS_CONTROL = 9  # 0 = local operation: the drive ignores the bus control word
STW_FREQUENCY_OK = 10
STW_RUNNING = 11
STW_BRAKE_FAULT = 12
STW_VOLTAGE_EXCEEDED = 13
STW_TORQUE_EXCEEDED = 14
STW_THERMAL_WARNING = 15

STATUS_FLAGS: Dict[int, str] = {
    STW_CONTROL_READY: 'control_ready',
    STW_UNIT_READY: 'unit_ready',
    STW_ENABLED: 'enabled',
    STW_TRIP: 'tripped',
    STW_ERROR_NO_TRIP: 'error_no_trip',
    STW_TRIP_LOCKED: 'trip_locked',
    STW_WARNING: 'warning',
    STW_ON_REFERENCE: 'on_reference',
    STW_BUS_CONTROL: 'bus_control',
    STW_FREQUENCY_OK: 'frequency_limit_ok',
    STW_RUNNING: 'running',
    STW_BRAKE_FAULT: 'resistor_brake_fault',
    STW_VOLTAGE_EXCEEDED: 'voltage_warning',
    STW_TORQUE_EXCEEDED: 'torque_warning',
    STW_THERMAL_WARNING: 'thermal_warning',
}
# Status bits that make /diagnostics WARN, with the words a technician reads.
WARNING_FLAGS: Dict[int, str] = {
    STW_WARNING: 'drive warning (see warning word)',
    STW_ERROR_NO_TRIP: 'drive error without trip',
    STW_BRAKE_FAULT: 'resistor brake fault',
    STW_VOLTAGE_EXCEEDED: 'DC link voltage too low or too high',
    STW_TORQUE_EXCEEDED: 'current or torque limit',
    STW_THERMAL_WARNING: 'thermal limit exceeded',
}


@dataclass(frozen=True)
class StatusWord:
    """A decoded FC-profile status word."""

    word: int

    def flag(self, index: int) -> bool:
        """Return status bit ``index``."""
        return bit(self.word, index)

    @property
    def tripped(self) -> bool:
        """Return whether bit 3 (trip) or bit 6 (trip locked) is set."""
        return self.flag(STW_TRIP) or self.flag(STW_TRIP_LOCKED)

    @property
    def bus_control(self) -> bool:
        """Return whether the drive obeys the bus control word (bit 9)."""
        return self.flag(STW_BUS_CONTROL)

    def flags(self) -> Dict[str, bool]:
        """Return every named flag."""
        return {name: self.flag(index) for index, name in STATUS_FLAGS.items()}

    def warnings(self) -> list:
        """Return the warning texts of the set warning bits."""
        return [text for index, text in WARNING_FLAGS.items() if self.flag(index)]

    def state(self, commanded_run: Optional[bool], reached_reference: bool) -> str:
        """
        Return the contract's state name.

        The status word alone cannot tell a start from a stop ramp, so the bridge says what
        it commanded: ``commanded_run`` (its control word asks to run; None: it has sent
        nothing, the drive runs under local or terminal control) and ``reached_reference``
        (the drive was on reference since that start).
        """
        if self.tripped:
            return 'tripped'
        if not (self.flag(STW_CONTROL_READY) and self.flag(STW_UNIT_READY)):
            return 'not_ready'
        if not self.flag(STW_RUNNING):
            return 'ready'
        if self.flag(STW_ON_REFERENCE) or not self.bus_control or commanded_run is None:
            return 'running'
        if commanded_run:
            return 'running' if reached_reference else 'starting'
        return 'stopping'
