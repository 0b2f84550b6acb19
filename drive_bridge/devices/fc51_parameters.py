"""
VLT Micro Drive FC 51 parameter table as data (family ``fc``, model ``fc51``).

Sources, in order of weight:

- manual 004 (``shared/manuals/004_59cc2fa01c5c97de.txt``, FC 51 Operating Instructions):
  section 4.4.1/4.4.2 (Quick Menu parameters: names, ranges, options, defaults), 5.5.4-5.5.6
  (worked frames: PNU 342 read as two registers, PNU 3 written as one, PNU 734 written as
  two with 65535 = 655.35 s), 5.6 (parameters the control word refers to), 6.2.1 (1-24
  has conversion index -2), 6.2.2/6.2.4 (what "change during operation" and the types mean),
  7.1.1 (16-90/16-92/16-94 bit tables), the specifications ("Ramp times 0.05 - 3600 sec.":
  the range of 3-81 as of 3-41/3-42);
- ``shared/research/protocols.md`` "FC-series parameters" (readouts 15-xx/16-xx with their
  type, conversion index and a confirmed/inferred/open status);
- :mod:`drive_bridge.devices.fc51` (the bridge's own entries; same type and conversion here);
- the FC series' Design Guides, "Network Configuration" (FC 111 section 8.7, FC 300 and VLT
  AQUA section 7.3.1, public copies found with the search tool): 8-30 Protocol (FC or Modbus
  RTU), 8-31 Address, 8-32 Baud Rate (2400-115200), 8-33 Parity/Stop Bits (even parity,
  1 stop bit by default). Manual 004 names only 8-33 (section 5.2.1); no source here gives
  the option numbers, 8-35 beyond its name, or 8-36 at all (left out).

What is missing: the FC 51 Programming Guide (MG02C6) parameter list, the only source of
every parameter's type, conversion index and change-during-operation flag, could not be
found in the stores searched (docs, pages, code); manual 004's own parameter overview
(chapter 6) lost its table in the text extraction. So this table holds the parameters the
sources above describe, not the whole drive. Where a field is not stated by a source it is
named in the entry's ``inferred``; the rules used:

- conversion index from the resolution of the range the manual prints (0.05-3600.00 s: -2;
  0.0-400 Hz: -1; 50-999 V: 0), the way section 6.2.1 describes it;
- data type: the register count a worked example shows, else the smallest FC-series type
  (section 6.2.4) whose range holds the printed limits after conversion; enumerations uint8;
  reference and feedback values (-4999-4999) as 16-01 Reference [Unit] (int32, index -3);
- ``setting``: groups 15 (drive information) and 16 (data readouts) are readouts.

``FC51_NAMED`` lists parameters that manual 004 names but gives nothing else for; read
them by giving the data type and conversion index (as the CLI asks for unknown numbers).
"""

from typing import Dict, Optional, Tuple

from drive_bridge.devices.parameters import ParameterSpec, TEXT

M4_QM1 = 'manual 004 section 4.4.1 (Quick Menu QM1)'
M4_QM2 = 'manual 004 section 4.4.2 (Quick Menu QM2)'
PROTOCOLS = 'protocols.md "FC-series parameters"'
TYPE_AND_INDEX = ('data_type', 'conversion')


def label(number: int) -> str:
    """Return a PNU as the FC manuals write it: 1614 -> '16-14', 3 -> '0-03'."""
    return f'{number // 100}-{number % 100:02d}'


def _p(number: int, name: str, data_type: str, conversion: int, source: str,
       inferred: Tuple[str, ...] = TYPE_AND_INDEX, setting: Optional[bool] = True,
       **fields) -> ParameterSpec:
    return ParameterSpec(number, name, data_type, conversion, source=source, setting=setting,
                         label=label(number), inferred=inferred, **fields)


def _readout(number: int, name: str, data_type: str, conversion: int, status: str,
             inferred: Tuple[str, ...] = (), **fields) -> ParameterSpec:
    return _p(number, name, data_type, conversion, f'{PROTOCOLS} ({status})', inferred,
              setting=False, **fields)


MOTOR_POWER_KW: Dict[int, str] = {  # manual 004 4.4.1, 1-20: [1] .. [16]
    1: '0.09 kW/0.12 HP', 2: '0.12 kW/0.16 HP', 3: '0.18 kW/0.25 HP', 4: '0.25 kW/0.33 HP',
    5: '0.37 kW/0.50 HP', 6: '0.55 kW/0.75 HP', 7: '0.75 kW/1.00 HP', 8: '1.10 kW/1.50 HP',
    9: '1.50 kW/2.00 HP', 10: '2.20 kW/3.00 HP', 11: '3.00 kW/4.00 HP', 12: '3.70 kW/5.00 HP',
    13: '4.00 kW/5.40 HP', 14: '5.50 kW/7.50 HP', 15: '7.50 kW/10.0 HP',
    16: '11.00 kW/15.00 HP',
}

# protocols.md: the FC 102 list of 8-04; the FC 51 subset is open, so the options are partial.
TIMEOUT_FUNCTIONS: Dict[int, str] = {
    0: 'Off', 1: 'Freeze output', 2: 'Stop', 3: 'Jogging', 4: 'Max. speed', 5: 'Stop and trip',
}

# The FC series' "Network Configuration" tables (FC 111 Design Guide section 8.7, FC 300 and
# VLT AQUA Design Guides 7.3.1, found with the search tool) name 8-30..8-33 and their settings
# but not their option numbers; manual 004 names only 8-33. The numbers below are the FC
# series' lists as we know them (inferred): read them on the drive before trusting them.
FC_NETWORK = 'FC-series Design Guides "Network Configuration" (FC 111 8.7, FC 300 7.3.1)'
PROTOCOLS_830: Dict[int, str] = {0: 'FC', 2: 'Modbus RTU'}
BAUD_RATES_832: Dict[int, str] = {
    0: '2400 Baud', 1: '4800 Baud', 2: '9600 Baud', 3: '19200 Baud', 4: '38400 Baud',
    5: '57600 Baud', 6: '76800 Baud', 7: '115200 Baud',
}
PARITY_833: Dict[int, str] = {
    0: 'Even Parity, 1 Stop Bit', 1: 'Odd Parity, 1 Stop Bit', 2: 'No Parity, 1 Stop Bit',
    3: 'No Parity, 2 Stop Bits',
}
# What the options mean on the line: (bus protocol, baud rate, (parity, stop bits)).
PROTOCOL_BY_OPTION: Dict[int, str] = {0: 'fc_protocol', 2: 'modbus_rtu'}
BAUD_BY_OPTION: Dict[int, int] = {
    number: int(text.split()[0]) for number, text in BAUD_RATES_832.items()}
FRAMING_BY_OPTION: Dict[int, Tuple[str, int]] = {0: ('E', 1), 1: ('O', 1), 2: ('N', 1),
                                                 3: ('N', 2)}

FC51_TABLE: Tuple[ParameterSpec, ...] = (
    # -- 0-** Operation/Display
    _p(3, 'Regional Settings', 'uint8', 0,
       'manual 004 example 5.5.5 (PNU 3 written as one register, value 1); uint8 as in fc.py',
       inferred=('data_type',)),
    # -- 1-** Load/Motor
    _p(100, 'Configuration Mode', 'uint8', 0, M4_QM2 + ': choose [3] for the PI controller',
       options={3: 'Process Closed Loop'}, options_partial=True),
    _p(120, 'Motor Power', 'uint8', 0,
       M4_QM1 + ': two sizes down, one size up from the drive rating; changing it changes '
       '1-22 to 1-25, 1-30, 1-33 and 1-35', options=MOTOR_POWER_KW, unit='kW'),
    _p(122, 'Motor Voltage', 'uint16', 0, M4_QM1 + ' (default 230/400 V by unit)',
       minimum=50, maximum=999, unit='V'),
    _p(123, 'Motor Frequency', 'uint16', 0, M4_QM1, minimum=20, maximum=400, unit='Hz',
       default=50),
    _p(124, 'Motor Current', 'uint32', -2,
       M4_QM1 + ' (range, default by motor type); manual 004 section 6.2.1: conversion index '
       '-2 (2.25 A is 225 on the bus); uint32 as in fc.py', inferred=('data_type',),
       minimum=0.01, maximum=26.0, unit='A'),
    _p(125, 'Motor Nominal Speed', 'uint16', 0, M4_QM1 + ' (default by motor type)',
       minimum=100, maximum=9999, unit='RPM'),
    _p(129, 'Automatic Motor Tuning (AMT)', 'uint8', 0,
       M4_QM1 + ': "cannot be changed while motor runs"',
       options={0: 'Off', 2: 'Enable AMT'}, default=0, change_running=False),
    # -- 3-** Reference/Ramps
    _p(302, 'Minimum Reference', 'int32', -3, M4_QM1 + ', ' + M4_QM2, minimum=-4999,
       maximum=4999, default=0.0),
    _p(303, 'Maximum Reference', 'int32', -3, M4_QM1 + ', ' + M4_QM2, minimum=-4999,
       maximum=4999, default=50.0),
    _p(310, 'Preset Reference', 'int16', -2,
       M4_QM2 + '; manual 004 section 5.6.2: four values [0]-[3] chosen by control word bits '
       '00/01', minimum=-100.0, maximum=100.0, unit='%', elements=4),
    _p(341, 'Ramp 1 Ramp-up Time', 'uint32', -2, M4_QM1 + ' (0 Hz to 1-23 Motor Frequency)',
       minimum=0.05, maximum=3600.0, unit='s', default=3.0),
    _p(342, 'Ramp 1 Ramp-down Time', 'uint32', -2,
       M4_QM1 + '; manual 004 example 5.5.4 reads it as two registers (32 bits)',
       inferred=('conversion',), minimum=0.05, maximum=3600.0, unit='s', default=3.0),
    _p(381, 'Quick Stop Ramp Time', 'uint32', -2,
       'manual 004 section 5.6.2 (control word bit 04); range: manual 004 specifications, '
       '"Ramp times 0.05 - 3600 sec." (as 3-41/3-42); type and index as in fc.py',
       minimum=0.05, maximum=3600.0, unit='s'),
    # -- 4-** Limits/Warnings
    _p(412, 'Motor Speed Low Limit [Hz]', 'uint16', -1, M4_QM2, minimum=0.0, maximum=400.0,
       unit='Hz'),
    _p(414, 'Motor Speed High Limit [Hz]', 'uint16', -1,
       M4_QM2 + ' ("default 65 Hz should normally be reduced to 50 - 55 Hz")', minimum=0.0,
       maximum=400.0, unit='Hz', default=65.0),
    # -- 6-** Analog In/Out (terminal 60, current input)
    _p(622, 'Terminal 60 Low Current', 'uint16', -2, M4_QM2 + ' (normally 0 or 4 mA)',
       minimum=0.0, maximum=19.99, unit='mA'),
    _p(623, 'Terminal 60 High Current', 'uint16', -2, M4_QM2 + ' ("normally (default) 20 mA")',
       minimum=0.01, maximum=20.0, unit='mA', default=20.0),
    _p(624, 'Terminal 60 Low Feedback Value', 'int32', -3, M4_QM2 + ' (value at 6-22)',
       minimum=-4999, maximum=4999),
    _p(625, 'Terminal 60 High Feedback Value', 'int32', -3, M4_QM2 + ' (value at 6-23)',
       minimum=-4999, maximum=4999),
    _p(626, 'Terminal 60 Filter Time Constant', 'uint16', -2, M4_QM2, minimum=0.01,
       maximum=10.0, unit='s'),
    # -- 7-** Controllers (process PI)
    _p(720, 'Process CL Feedback Resource', 'uint8', 0, M4_QM2 + ': choose [2] analog input 60',
       options={2: 'Analog input 60'}, options_partial=True),
    _p(732, 'Process PI Start Speed', 'uint16', -1, M4_QM2, minimum=0.0, maximum=200.0,
       unit='Hz'),
    _p(733, 'Process PI Proportional Gain', 'uint16', -2, M4_QM2, minimum=0.0, maximum=10.0),
    _p(734, 'Process PI Integral Time', 'uint32', -2,
       M4_QM2 + '; manual 004 example 5.5.6 writes 65535 (655.35 s) as two registers',
       inferred=(), minimum=0.10, maximum=9999.0, unit='s'),
    _p(738, 'Process Feed Forward Factor', 'uint16', 0, M4_QM2, minimum=0, maximum=400,
       unit='%'),
    # -- 8-** Communications
    _p(803, 'Control Word Timeout Time', 'uint32', -1,
       'fc.py (inferred from FC 102/300 material)', inferred=('name',) + TYPE_AND_INDEX,
       unit='s'),
    _p(804, 'Control Word Timeout Function', 'uint8', 0,
       PROTOCOLS + ' (FC 102 option list; the FC 51 subset is open)',
       inferred=('name', 'data_type'), options=TIMEOUT_FUNCTIONS, options_partial=True),
    # The drive's serial line: backed up, never written by a restore (serial_line).
    _p(830, 'Protocol', 'uint8', 0,
       FC_NETWORK + ': "8-30 Protocol" FC or Modbus RTU; FC by default (docs/fc51.md); the '
       'option numbers are those of the FC series (not in manual 004)',
       inferred=TYPE_AND_INDEX + ('options', 'default'), options=PROTOCOLS_830,
       options_partial=True, default=0, serial_line=True),
    _p(831, 'Address', 'uint8', 0,
       'manual 004 section 5.2.4 (slave addresses 1-247); ' + FC_NETWORK + ': "8-31 Address"',
       inferred=TYPE_AND_INDEX, minimum=1, maximum=247, serial_line=True),
    _p(832, 'Baud Rate', 'uint8', 0,
       FC_NETWORK + ': "8-32 Baud Rate" 2400-115200; 9600 by default (fc_telegram.py); the '
       'option numbers are those of the FC series (not in manual 004)',
       inferred=TYPE_AND_INDEX + ('options', 'default'), options=BAUD_RATES_832,
       options_partial=True, default=2, serial_line=True),
    _p(833, 'Parity / Stop Bits', 'uint8', 0,
       'manual 004 section 5.2.1 ("1 bit for even/odd parity is used; 1 or 2 stop bits if no '
       'parity is selected (see par. 8-33)"); ' + FC_NETWORK + ': even parity, 1 stop bit by '
       'default; the option numbers are those of the FC series (not in manual 004)',
       inferred=TYPE_AND_INDEX + ('options',), options=PARITY_833, default=0,
       serial_line=True),
    # -- 15-** Drive Information
    _readout(1500, 'Operating Hours', 'uint32', 74, 'confirmed', unit='h'),
    _readout(1501, 'Running Hours', 'uint32', 74, 'confirmed', unit='h'),
    _readout(1540, 'FC Type', TEXT, 0, 'confirmed', characters=20),
    _readout(1543, 'Software Version', TEXT, 0,
             'confirmed; manual 004 section 1: the software version is read here',
             characters=20),
    # -- 16-** Data Readouts
    _readout(1600, 'Control Word', 'uint16', 0, 'confirmed: 16 bit; unsigned inferred'),
    _readout(1601, 'Reference [Unit]', 'int32', -3, 'confirmed'),
    _readout(1602, 'Reference %', 'int16', -1, 'confirmed', unit='%'),
    _readout(1603, 'Status Word', 'uint16', 0, 'inferred', TYPE_AND_INDEX),
    _readout(1605, 'Main Actual Value [%]', 'int16', -2, 'open: 16 bit', TYPE_AND_INDEX,
             unit='%'),
    _readout(1610, 'Power [kW]', 'int32', 1, 'inferred; FC 51 scaling open', TYPE_AND_INDEX,
             unit='kW'),
    _readout(1612, 'Motor Voltage', 'uint16', -1, 'inferred', TYPE_AND_INDEX, unit='V'),
    _readout(1613, 'Frequency', 'uint16', -1, 'inferred', TYPE_AND_INDEX, unit='Hz'),
    _readout(1614, 'Motor Current', 'int32', -2, 'confirmed: 32 bit, x100', unit='A'),
    _readout(1618, 'Motor Thermal', 'uint8', 0, 'inferred', TYPE_AND_INDEX, unit='%'),
    _readout(1630, 'DC Link Voltage', 'uint16', 0, 'inferred', TYPE_AND_INDEX, unit='V'),
    _readout(1634, 'Heatsink Temp.', 'uint8', 100, 'inferred: index 100, raw = degrees C',
             TYPE_AND_INDEX, unit='C'),
    _readout(1690, 'Alarm Word', 'uint32', 0, 'inferred; bits: manual 004 section 7.1.1',
             TYPE_AND_INDEX),
    _readout(1692, 'Warning Word', 'uint32', 0, 'open; bits: manual 004 section 7.1.1',
             TYPE_AND_INDEX),
    _readout(1694, 'Ext. Status Word', 'uint32', 0, 'open; bits: manual 004 section 7.1.1',
             TYPE_AND_INDEX),
)
FC51_PARAMETERS: Dict[int, ParameterSpec] = {spec.number: spec for spec in FC51_TABLE}

# Named by manual 004, nothing else known: number -> (name as the manual writes it, where).
FC51_NAMED: Dict[int, Tuple[str, str]] = {
    10: ('Active Set-up', 'manual 004 section 5.6.2, control word bit 13 ("Multi set-ups")'),
    190: ('Motor Thermal Protection', 'manual 004, motor overload note (option "ETR trip")'),
    201: ('DC Brake Current', 'manual 004 section 5.6.2, control word bit 02'),
    202: ('DC Braking Time', 'manual 004 section 5.6.2, control word bit 02'),
    319: ('Jog Speed', 'manual 004 section 5.6.2, control word bit 08'),
    416: ('torque limit (see 3-41)', 'manual 004 section 4.4.1, par. 3-41'),
    417: ('regenerative torque limit (see 3-42)', 'manual 004 section 4.4.1, par. 3-42'),
    540: ('Function Relay', 'manual 004 section 5.6.2, control word bit 11'),
    619: ('(set to match S200 switch 4)', 'manual 004 section 3.5, table 3.5'),
    730: ('Process PI Normal/Inverse', M4_QM2 + ' ("most PI controllers are Normal")'),
    731: ('Process PI Anti Windup', M4_QM2 + ' ("leave Enabled normally")'),
    835: ('Minimum Response Delay', 'protocols.md "pymodbus" (RS-485 practice)'),
    850: ('Coasting Select', 'manual 004 section 5.6.2, control word bit 03'),
    853: ('Start Select', 'manual 004 section 5.6.2, control word bit 06'),
    854: ('Reversing Select', 'manual 004 section 5.6.2, control word bit 15'),
    855: ('Set-up Select', 'manual 004 section 5.6.2, control word bit 13'),
    856: ('Preset Reference Select', 'manual 004 section 5.6.2, control word bits 00/01'),
}
# Manual 004 section 5.6.2 refers to these ranges without naming each parameter.
FC51_NAMED_RANGES: Tuple[Tuple[int, int, str], ...] = (
    (340, 347, 'Ramp 1 (control word bit 09 = 0)'),
    (350, 357, 'Ramp 2 (control word bit 09 = 1)'),
    (510, 515, 'Digital inputs (Speed up/Slow down, DC brake, coasting, reset)'),
)
