"""
FC-profile bus reference scaling: 0x4000 = 100 %, signed, two's complement for reverse.

Source: VLT 5000/6000 Modbus RTU option card manual (40 % is written as 0x1999) and the
FC 51 manual, chapter 5 (bus speed reference). ``int(percent * 0x4000 / 100)`` rounds
toward zero, as the manual does (6553.6 -> 6553).
"""

import math

FULL_SCALE_WORD = 0x4000
MIN_PERCENT = -200.0
MAX_PERCENT = 200.0  # exclusive: +200 % would be 0x8000, which is -200 % as a signed word


def check_percent(percent: float) -> float:
    """Return ``percent`` as a float if it is a finite value in [-200, 200), else raise."""
    value = float(percent)
    if math.isnan(value) or math.isinf(value):
        raise ValueError(f'speed reference must be a finite number, got {percent!r}')
    if not MIN_PERCENT <= value < MAX_PERCENT:
        raise ValueError(f'speed reference {value} % is out of range [-200, 200)')
    return value


def percent_to_word(percent: float) -> int:
    """Encode a speed reference in percent as a 16-bit bus reference word."""
    value = check_percent(percent)
    scaled = int(value * FULL_SCALE_WORD / 100.0)
    return scaled & 0xFFFF


def word_to_percent(word: int) -> float:
    """Decode a 16-bit bus reference or actual value word to percent."""
    word &= 0xFFFF
    signed = word - 0x10000 if word & 0x8000 else word
    return signed * 100.0 / FULL_SCALE_WORD
