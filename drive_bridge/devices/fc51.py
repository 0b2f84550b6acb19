"""
VLT Micro Drive FC 51 over its built-in Modbus RTU (family ``fc``).

Tables from the FC 51 manual ``004_59cc2fa01c5c97de.txt`` (chapter 5, section 7.1.1) and
``shared/research/protocols.md`` (parameter types, alarm numbers), each with its source.
Other FC-series drives share this map; a new model is a new entry in ``MODELS``/``READOUTS``.
"""

from typing import Dict, Optional, Tuple

from drive_bridge.devices.contracts import Family
from drive_bridge.devices.fc51_parameters import FC51_PARAMETERS
from drive_bridge.devices.fc_profile_drive import (
    COMMS_TIMEOUT, CURRENT_PARAMETER, DriveFamilyData, make_drive_profile)
from drive_bridge.devices.parameters import FC_CONVERSION_FACTORS, ParameterSpec
from drive_bridge.settings import Setting

FAMILY = 'fc'
MODELS = ('auto', 'fc51')
ADDRESS_RANGE = (1, 247)  # manual 004 section 5.2.4; par. 8-31 sets it

# Coils (manual 004 section 5.2.8, coil table): number - 1 = coil address.
COIL_CONTROL = 0  # coils 1-16 control word, 17-32 reference: one 0F write of 32 coils
COIL_STATUS = 32  # coils 33-48 status word, 49-64 main actual value: one 01 read of 32
COIL_EEPROM = 64  # coil 65: 1 = parameter writes go to RAM and EEPROM
# Holding registers (section 5.2.8, table 5.1): register number - 1.
REGISTER_LAST_ERROR = 6  # register 7: detail of the last exception 04
REGISTER_INDEX = 8  # register 9: array index of indexed parameters


# Every parameter known of the FC 51, with its source (:mod:`.fc51_parameters`).
PARAMETERS: Dict[int, ParameterSpec] = FC51_PARAMETERS
# Holding registers of the process data (section 5.2.8): 50000 CTW, 50010 REF, 50200 STW,
# 50210 MAV (frame address = number - 1); a parameter number mapping onto them is refused.
PROCESS_REGISTERS = (49999, 50009, 50199, 50209)

# What the bridge polls, per model (the names are the DeviceReading fields they fill).
READOUTS: Dict[str, Dict[str, int]] = {
    'fc51': {'motor_current': 1614, 'frequency': 1613, 'motor_thermal': 1618,
             'alarm_word': 1690, 'warning_word': 1692, 'extended_status': 1694},
}

# Manual 004 section 7.1.1 "Alarm, Warning and Extended Status Word", par. 16-90 column:
# bit -> (the LCP alarm number, name). Alarm numbers from protocols.md (inferred from FC 300
# material, a table to correct); bits without a known number report 1000 + bit.
ALARM_BITS: Dict[int, Tuple[int, str]] = {
    0: (28, 'Brake check'),
    1: (69, 'Power card temperature'),
    2: (14, 'Earth fault'),
    4: (17, 'Control word timeout'),
    5: (13, 'Over current'),
    7: (11, 'Motor thermistor over temperature'),
    8: (10, 'Motor ETR over temperature'),
    9: (9, 'Inverter overload'),
    10: (8, 'DC under voltage'),
    11: (7, 'DC over voltage'),
    12: (16, 'Short circuit'),
    14: (4, 'Mains phase loss'),
    15: (1015, 'AMT not OK'),
    16: (2, 'Live zero error'),
    17: (38, 'Internal fault'),
    19: (30, 'U phase loss'),
    20: (31, 'V phase loss'),
    21: (32, 'W phase loss'),
    23: (1023, 'Control voltage fault'),
    26: (1026, 'Brake resistor short circuit'),
    27: (1027, 'Brake IGBT short circuit'),
    29: (1029, 'Drive initialised'),
    31: (1031, 'Mechanical brake low'),
}
# Same table, par. 16-92 column.
WARNING_BITS: Dict[int, str] = {
    1: 'Power card temperature', 4: 'Control word timeout', 5: 'Over current',
    6: 'Torque limit', 7: 'Motor thermistor over temperature',
    8: 'Motor ETR over temperature', 9: 'Inverter overload', 10: 'DC under voltage',
    11: 'DC over voltage', 14: 'Mains phase loss', 16: 'Live zero error',
    25: 'Current limit', 28: 'Motor phase missing', 30: 'Undefined',
}
# Same table, par. 16-94 column.
EXTENDED_STATUS_BITS: Dict[int, str] = {
    0: 'Ramping', 2: 'Start CW/CCW', 3: 'Slow down', 4: 'Catch up',
    7: 'Output current high', 8: 'Output current low', 13: 'Braking', 15: 'OVC active',
    16: 'AC brake', 31: 'Database busy',
}

# Manual 004 section 5.3.2: Modbus exception codes, and the detail in register 7 after 04.
EXCEPTIONS: Dict[int, str] = {
    1: 'illegal function (the drive does not support this function code)',
    2: 'illegal data address (no such register or coil, or the length runs past its end)',
    3: 'illegal data value (malformed request)',
    4: 'slave device failure (the drive could not carry out the request)',
}
LAST_ERROR_DETAILS: Dict[int, str] = {
    0: 'the parameter number does not exist',
    1: 'there is no write access to the parameter',
    2: 'the data value exceeds the parameter limits',
    3: 'the sub-index in use does not exist',
    5: 'the data type does not match the parameter called',
    17: 'data change in the parameter is not possible in the present mode '
        '(stop the motor first)',
    18: 'other error',
    130: 'there is no bus access to the parameter called',
}


def explain_exception(code: int, detail: Optional[int] = None) -> str:
    """Return technician text for a Modbus exception, with register 7's detail if read."""
    text = EXCEPTIONS.get(code, 'exception code not in the FC 51 manual')
    if detail is not None:
        text = f'{LAST_ERROR_DETAILS.get(detail, "unknown detail")} (register 7 = {detail}); ' \
               f'{text}'
    return f'{text}, Modbus exception {code:02d}'


def parameter_label(number: int) -> str:
    """Return a PNU as the FC manuals write it: 1614 -> '16-14', 3 -> '0-03'."""
    return f'{number // 100}-{number % 100:02d}'


def model_from_type(type_text: str) -> Optional[str]:
    """Return the model that par. 15-40 FC type names ("FC-051P..." on an FC 51), or None."""
    compact = type_text.upper().replace(' ', '').replace('-', '')
    return 'fc51' if compact.startswith(('FC051', 'FC51')) else None


DATA = DriveFamilyData(
    name=FAMILY, models=MODELS, parameters=PARAMETERS, readouts=READOUTS,
    conversion_factors=FC_CONVERSION_FACTORS, alarm_bits=ALARM_BITS,
    warning_bits=WARNING_BITS, extended_status_bits=EXTENDED_STATUS_BITS,
    explain_exception=explain_exception, detail_register=REGISTER_LAST_ERROR,
    index_register=REGISTER_INDEX, eeprom_coil=COIL_EEPROM,
    identify_parameter=1540, version_parameter=1543, model_from_type=model_from_type,
    timeout_time_parameter=803, timeout_function_parameter=804,
    parameter_label=parameter_label, process_registers=PROCESS_REGISTERS)

COMMS_TIMEOUT_FUNCTION = Setting(
    'comms_timeout_function', int, -1,
    'drives: what the drive does on a control word timeout (FC: par. 8-04; 0 off, 1 freeze, '
    '2 stop, 3 jog, 4 max speed, 5 stop and trip); -1 = leave as set',
    choices=(-1, 0, 1, 2, 3, 4, 5))

ENTRY = Family(
    name=FAMILY, description='VLT Micro Drive FC 51, built-in Modbus RTU',
    models=MODELS, address_range=ADDRESS_RANGE,
    protocols=('modbus_rtu', 'modbus_tcp', 'rtu_over_tcp', 'fc_protocol'),
    settings=(COMMS_TIMEOUT, COMMS_TIMEOUT_FUNCTION, CURRENT_PARAMETER),
    make_profile=make_drive_profile(DATA), reference=True)
