"""
LVSG Motor Starter Profile 2 as the MCD 200 Profibus Module uses it: the process bytes. Pure.

Source: MCD 200 Profibus Module manual ``002_8ae547a04c1e19a0.txt`` ("LVSG Motor Starter
Profile 2 Data Structure", "... with Extended Data Structure", "Profibus Diagnostic
Telegrams"). Master -> slave: control bytes 0 and 1, then (extended module) one operating
parameter request byte. Slave -> master: status bytes 0 and 1, then (extended) four bytes
answering the request.
"""

from dataclasses import dataclass
from typing import Dict, Optional, Tuple

from drive_bridge.protocol.words import bit, bits

# Control word (master > slave).
CONTROL_FWD_RUN = (0, 0)  # (byte, bit)
CONTROL_RESET = (0, 3)
CONTROL_QUICK_STOP = (1, 4)  # manufacturer-defined: the stop on Fwd Run 1 -> 0 is a coast
# Status word (slave > master).
STATUS_READY = (0, 0)
STATUS_ON = (0, 1)  # starting, running or soft stopping
STATUS_FAULT = (0, 2)  # tripped
STATUS_RAMPING = (1, 7)  # starting or soft stopping
CURRENT_PCT_BITS = (0, 5)  # byte 1 bits 0-5: motor current in % FLC, 63 = 200 %
CURRENT_FULL_SCALE = 63
CURRENT_DIVISOR = 0.315  # "To render this value as a readable percentage, divide by 0.315"

BASIC_OUTPUT_BYTES, BASIC_INPUT_BYTES = 2, 2
EXTENDED_OUTPUT_BYTES, EXTENDED_INPUT_BYTES = 3, 6

# Operating parameters of the extended module.
PARAMETER_PRODUCT = 1  # high byte: product type (bits 7-3, = 4); low byte: software version
PARAMETER_STATE = 2  # high byte: trip code; low byte: state (bits 0-3) and flags (4-7)
PARAMETER_CURRENT = 3  # average current in A, 16 bits
PARAMETER_TEMPERATURE = 4  # low byte: motor temperature (% of thermal capacity)
PARAMETERS = (PARAMETER_PRODUCT, PARAMETER_STATE, PARAMETER_CURRENT, PARAMETER_TEMPERATURE)
MCD200_PRODUCT_TYPE = 4
# "All MCD 201 open loop soft starter models will read back average current as '2222'
# decimal and motor temperature as '111' decimal."
MCD201_CURRENT_PLACEHOLDER = 2222
MCD201_TEMPERATURE_PLACEHOLDER = 111

# Parameter 2 low byte, bits 0-3: MCD 200 status -> the contract's state names.
MCD200_STATES: Dict[int, str] = {
    0: 'unknown',  # communication error between module and MCD 200
    1: 'ready', 2: 'starting', 3: 'running', 4: 'stopping',
    5: 'restart_delay',  # "Not Ready (Restart delay)"
    6: 'tripped',
}
STATE_BIT_POSITIVE_ROTATION = 4
STATE_BIT_CURRENT_ABOVE_FLC = 5
STATE_BIT_ROTATION_VALIDATED = 6
STATE_BIT_COMMS_FAILURE = 7
# Parameter 2 high byte: MCD 200 trip codes (* = MCD 202 closed loop models only).
NO_TRIP = 255
MCD200_TRIPS: Dict[int, Tuple[str, bool]] = {
    1: ('Excess start time', True), 2: ('Motor overload', True),
    3: ('Motor thermistor', True), 4: ('Phase imbalance', True),
    5: ('Supply frequency', False), 6: ('Phase rotation', True), 8: ('Power circuit', False),
    15: ('Communication failure between module and MCD 200', False),
    16: ('Communication failure between module and network', False),
}


def _set(data: bytearray, position: Tuple[int, int], on: bool) -> None:
    byte, index = position
    if on:
        data[byte] |= 1 << index
    else:
        data[byte] &= ~(1 << index) & 0xFF


@dataclass(frozen=True)
class Control:
    """The master's control bits and (extended module) parameter request."""

    fwd_run: bool = False
    reset: bool = False
    quick_stop: bool = False
    parameter_request: int = 0

    def encode(self, extended: bool) -> bytes:
        """Return the output bytes: 2 (basic) or 3 (extended)."""
        data = bytearray(EXTENDED_OUTPUT_BYTES if extended else BASIC_OUTPUT_BYTES)
        _set(data, CONTROL_FWD_RUN, self.fwd_run)
        _set(data, CONTROL_RESET, self.reset)
        _set(data, CONTROL_QUICK_STOP, self.quick_stop)
        if extended:
            data[2] = self.parameter_request & 0xFF
        return bytes(data)

    @classmethod
    def decode(cls, data: bytes) -> 'Control':
        """Return the control bits of output bytes (a gateway's image read back)."""
        if len(data) < BASIC_OUTPUT_BYTES:
            raise ValueError(f'LVSG output has {len(data)} bytes: expected 2 or 3')
        return cls(fwd_run=bit(data[0], CONTROL_FWD_RUN[1]), reset=bit(data[0], CONTROL_RESET[1]),
                   quick_stop=bit(data[1], CONTROL_QUICK_STOP[1]),
                   parameter_request=data[2] if len(data) > 2 else 0)


@dataclass(frozen=True)
class Status:
    """The slave's status bits and % FLC current, and the extended parameter answer."""

    ready: bool
    on: bool
    fault: bool
    ramping: bool
    current_raw: int  # 0-63
    invalid_parameter: bool = False
    parameter: Optional[int] = None  # echoed parameter number (extended)
    value: Optional[int] = None  # 16-bit value: high byte << 8 | low byte

    @property
    def current_pct_flc(self) -> float:
        """Return the motor current in % FLC (63 = 200 %)."""
        return self.current_raw / CURRENT_DIVISOR


def decode_status(data: bytes) -> Status:
    """Decode 2 (basic) or 6 (extended) input bytes; raise ValueError on a wrong length."""
    if len(data) not in (BASIC_INPUT_BYTES, EXTENDED_INPUT_BYTES):
        raise ValueError(f'LVSG input has {len(data)} bytes: expected 2 or 6')
    status = {'ready': bit(data[0], STATUS_READY[1]), 'on': bit(data[0], STATUS_ON[1]),
              'fault': bit(data[0], STATUS_FAULT[1]),
              'ramping': bit(data[1], STATUS_RAMPING[1]),
              'current_raw': bits(data[1], *CURRENT_PCT_BITS)}
    if len(data) == EXTENDED_INPUT_BYTES:
        status.update(invalid_parameter=bit(data[2], 0), parameter=data[3],
                      value=data[5] << 8 | data[4])
    return Status(**status)


def encode_status(ready: bool, on: bool, fault: bool, ramping: bool, current_raw: int,
                  answer: Optional[Tuple[int, int, bool]] = None) -> bytes:
    """Return input bytes; ``answer`` = (parameter, value, invalid) for the extended module."""
    data = bytearray(EXTENDED_INPUT_BYTES if answer is not None else BASIC_INPUT_BYTES)
    _set(data, STATUS_READY, ready)
    _set(data, STATUS_ON, on)
    _set(data, STATUS_FAULT, fault)
    _set(data, STATUS_RAMPING, ramping)
    data[1] |= max(0, min(CURRENT_FULL_SCALE, current_raw))
    if answer is not None:
        parameter, value, invalid = answer
        data[2], data[3] = int(invalid), parameter
        data[4], data[5] = value & 0xFF, value >> 8 & 0xFF
    return bytes(data)


def current_raw_from_pct(pct_flc: float) -> int:
    """Return the 6-bit % FLC value (63 = 200 %) of a current in % FLC."""
    return max(0, min(CURRENT_FULL_SCALE, round(pct_flc * CURRENT_DIVISOR)))


def split_state_parameter(value: int) -> Tuple[int, int]:
    """Split parameter 2 into (trip code, state byte)."""
    return value >> 8 & 0xFF, value & 0xFF


def product_type(value: int) -> int:
    """Return the product type code of parameter 1 (high byte, bits 7-3)."""
    return value >> 8 >> 3 & 0x1F


def trip_name(code: int) -> str:
    """Return the MCD 200 trip name of ``code`` ('' for 255, no trip)."""
    if code == NO_TRIP:
        return ''
    entry = MCD200_TRIPS.get(code)
    return entry[0] if entry else f'unknown MCD 200 trip code {code}'


def decode_diagnostic(telegram: bytes) -> int:
    """Return the trip code of the 3-byte diagnostic telegram (length 3, trip, reserved)."""
    if len(telegram) != 3 or telegram[0] != 3:
        raise ValueError(f'diagnostic telegram {telegram.hex(" ")} is not length 3, trip, '
                         'reserved')
    return telegram[1]
