"""
VLT 5000 and VLT 6000 HVAC parameter tables as data (family ``vlt``), per model.

Sources:

- manual 003 (``shared/manuals/003_be38f660678fad2b.txt``, Modbus RTU option card):
  "Message Translation Examples" 4-6 (par. 104 uint16 index 0, par. 514 uint32 index -2,
  par. 533 text, VLT 6000 only), "Conversion Factor" (par. 201, factor 0.1), "VLT 6000
  Parameter Settings" (500-502 and their defaults), "Register Maps" (the parameter number
  ranges the card maps, with the first and last name of each group);
- ``shared/research/protocols.md`` "VLT 5000/6000 readouts" and the VLT 5000 FC-protocol
  vector (par. 520 read as a double word: 0x020C = 5.24 A);
- public copies of Danfoss manuals found with the search tool, cited per entry:
  VLT 5000 Design Guide MG.52.B2.02 ("Additional Text": par. 001 values 0-5), VLT 5000
  Crane Design Guide MG.50.N4.02 (par. 615 indexed; 621-631 nameplate data are data type 9,
  text), VLT 6000 HVAC MG.61.B5.02 / MG.60.B1.02 (201/202 output frequency limits),
  VLT 5000/5000 Flux/6000/8000 PROFIBUS MG.90.D1.02 (203 reference range, 205 index -3).

What is missing: the "Factory settings" list of the VLT 5000 and VLT 6000 manuals (every
parameter with its range, change during operation, 4-setup, conversion index and data
type) could not be found in the stores searched (docs, pages, code); the stored copies hold
their serial-communication pages only. So these tables hold what the sources above state,
not the whole drives. Fields no source states are named in the entry's ``inferred``
(enumerations uint8; a readout's 32-bit word uint32, as in vlt.py). ``VLT_NAMED`` lists
parameters with a sourced name and nothing else; ``VLT6000_NUMBER_RANGES`` the numbers the
option card maps on a VLT 6000 (a number outside them is no parameter there).
"""

from typing import Dict, Tuple

from drive_bridge.devices.parameters import ParameterSpec, TEXT

MODELS = ('vlt5000', 'vlt6000')
M3 = 'manual 003'
PROTOCOLS = 'protocols.md "VLT 5000/6000 readouts"'
MG52B2 = 'VLT 5000 Design Guide MG.52.B2.02 (public copy)'
MG50N4 = 'VLT 5000 Crane Design Guide MG.50.N4.02 (public copy)'
MG61B5 = 'VLT 6000 HVAC Design Guide MG.61.B5.02 and MG.60.B1.02 (public copies)'
MG90D1 = 'VLT 5000/5000 Flux/6000/8000 PROFIBUS manual MG.90.D1.02 (public copy)'
TYPE_AND_INDEX = ('data_type', 'conversion')


def _setting(number: int, name: str, data_type: str, conversion: int, source: str,
             inferred: Tuple[str, ...] = TYPE_AND_INDEX, **fields) -> ParameterSpec:
    return ParameterSpec(number, name, data_type, conversion, source=source, setting=True,
                         inferred=inferred, **fields)


def _readout(number: int, name: str, data_type: str, conversion: int, source: str,
             inferred: Tuple[str, ...] = TYPE_AND_INDEX, **fields) -> ParameterSpec:
    return ParameterSpec(number, name, data_type, conversion, source=source, setting=False,
                         inferred=inferred, **fields)


COMMON: Tuple[ParameterSpec, ...] = (
    _setting(104, 'Motor Frequency', 'uint16', 0,
             M3 + ' example 4 (60 Hz written as 0x003C: data type 6, conversion 0)',
             inferred=(), unit='Hz'),
    _setting(201, 'Output Frequency Low Limit (Minimum Frequency)', 'uint16', -1,
             M3 + ' "Conversion Factor" (10 Hz is 100 on the bus); name: ' + MG61B5,
             inferred=('data_type',), unit='Hz'),
    _readout(538, 'Alarm Word', 'uint32', 0, PROTOCOLS + ' (number confirmed; type as vlt.py)'),
    _readout(540, 'Warning Word', 'uint32', 0,
             PROTOCOLS + ' (number confirmed; type as vlt.py)'),
    _readout(541, 'Extended Status Word', 'uint32', 0,
             PROTOCOLS + ' (number confirmed; type as vlt.py)'),
    _readout(953, 'Communication Warning Word', 'uint16', 0,
             PROTOCOLS + ' (number confirmed; type as vlt.py)'),
)

LANGUAGES_VLT5000: Dict[int, str] = {
    0: 'English', 1: 'Deutsch', 2: 'Français', 3: 'Dansk', 4: 'Espanol', 5: 'Italiano',
}

VLT5000_ONLY: Tuple[ParameterSpec, ...] = (
    _setting(1, 'Language', 'uint8', 0, MG52B2 + ' "Additional Text": values 0-5',
             options=LANGUAGES_VLT5000),
    _readout(520, 'Motor Current', 'uint32', -2,
             'protocols.md: VLT 5000 FC-protocol vector reads it as a double word, '
             '0x0000020C = 5.24 A (unsigned inferred)', inferred=(), unit='A'),
) + tuple(
    _readout(number, f'Nameplate data (par. {number})', TEXT, 0,
             MG50N4 + ': "parameters 621-631 (nameplate data) have data type 9"',
             inferred=('name',))
    for number in range(621, 632))

VLT6000_ONLY: Tuple[ParameterSpec, ...] = (
    _readout(514, 'Motor Current', 'uint32', -2,
             M3 + ' example 5 (3 A read as 0x0000012C: data type 7, conversion -2)',
             inferred=(), unit='A'),
    _setting(533, 'Display Text 1', TEXT, 0,
             M3 + ' example 6 (VLT 6000 only; data type 9); at most 20 characters ("Text '
             'Blocks"); a setting: inferred', inferred=('setting',)),
    _readout(631, 'Nameplate: Communication Option Ordering No.', TEXT, 0,
             M3 + ' "Register Maps" (name); text as VLT 5000 621-631 (' + MG50N4 + ')',
             inferred=('data_type',)),
)

VLT_PARAMETERS: Dict[str, Dict[int, ParameterSpec]] = {
    'vlt5000': {spec.number: spec for spec in COMMON + VLT5000_ONLY},
    'vlt6000': {spec.number: spec for spec in COMMON + VLT6000_ONLY},
}

_COMMON_NAMED: Dict[int, Tuple[str, str]] = {
    203: ('reference range: 0 = refMIN to refMAX, 1 = -refMAX to +refMAX',
          MG90D1 + ' "Bus reference value"'),
    205: ('(a reference in Hz: conversion index -3, 15200 = 15.200 Hz)',
          MG90D1 + ' "Size attribute" example'),
}
VLT_NAMED: Dict[str, Dict[int, Tuple[str, str]]] = {
    'vlt5000': {
        **_COMMON_NAMED,
        615: ('Error code (indexed; values 1-99)', MG50N4 + ' "Index" example'),
    },
    'vlt6000': {
        **_COMMON_NAMED,
        1: ('Language', M3 + ' "Register Maps"'),
        17: ('Operating State at Power-up', M3 + ' "Register Maps"'),
        100: ('Configuration', M3 + ' "Register Maps"'),
        117: ('Motor Thermal Protection', M3 + ' "Register Maps"'),
        200: ('Output Frequency Range', M3 + ' "Register Maps"'),
        202: ('Output Frequency High Limit', MG61B5 + ' "Present output frequency"'),
        228: ('Warning: High Feedback', M3 + ' "Register Maps"'),
        300: ('Terminal 16 Digital Input', M3 + ' "Register Maps"'),
        328: ('Pulse Feedback, Max. Freq.', M3 + ' "Register Maps"'),
        400: ('Reset Function', M3 + ' "Register Maps"'),
        427: ('PID Lowpass Filter Time', M3 + ' "Register Maps"'),
        500: ('Protocol (default: FC protocol, as the card needs)',
              M3 + ' "VLT 6000 Parameter Settings"'),
        501: ('Address (default 001, as the card needs)', M3 + ' "VLT 6000 Parameter Settings"'),
        502: ('Baud Rate (default 9600 baud, as the card needs)',
              M3 + ' "VLT 6000 Parameter Settings"'),
        566: ('FLN Time Function', M3 + ' "Register Maps"'),
        600: ('Operating Data: Operating Hours', M3 + ' "Register Maps"'),
        700: ('Relay 6, Output Function', M3 + ' "Register Maps"'),
        711: ('Relay 9, Off Delay', M3 + ' "Register Maps"'),
    },
}

# Manual 003 "Register Maps": the parameter numbers the option card maps (first, last).
VLT6000_NUMBER_RANGES: Tuple[Tuple[int, int], ...] = (
    (1, 17), (100, 117), (200, 228), (300, 328), (400, 427), (500, 566), (600, 631),
    (700, 711),
)


def in_vlt6000_map(number: int) -> bool:
    """Return whether the option card maps parameter ``number`` on a VLT 6000."""
    return any(first <= number <= last for first, last in VLT6000_NUMBER_RANGES)
