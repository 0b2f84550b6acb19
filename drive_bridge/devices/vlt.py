"""
VLT 5000 and VLT 6000 HVAC with the Modbus RTU option card (family ``vlt``).

Tables from the option card manual ``003_be38f660678fad2b.txt`` ("Memory Mapping",
"Conversion Factor", "Message Translation Examples", "Exception Codes") and
``shared/research/protocols.md`` ("VLT 5000/6000 readouts"), each with its source. The
process data, control and status words are the FC profile's
(:mod:`drive_bridge.devices.fc_profile_drive`).
"""

from typing import Dict, Optional

from drive_bridge.devices.contracts import Family
from drive_bridge.devices.fc_profile_drive import (
    COMMS_TIMEOUT, CURRENT_PARAMETER, DriveFamilyData, make_drive_profile)
from drive_bridge.devices.parameters import ParameterSpec, VLT_CONVERSION_FACTORS
from drive_bridge.devices.vlt_parameters import VLT_PARAMETERS
from drive_bridge.settings import Setting

FAMILY = 'vlt'
# The option card cannot report which drive it sits in: the model must be configured.
MODELS = ('vlt5000', 'vlt6000')
ADDRESS_RANGE = (1, 247)  # "Address and Termination" DIP switch: 01 ... F7

# "Register Maps": register number - 1 = frame address.
REGISTER_IND = 0  # register 1: IND, the index word (low byte: array index)
REGISTER_MODBUS_TIMEOUT = 1  # register 2: Modbus communications timeout, 10 ms units
REGISTER_DRIVE_TIMEOUT = 2  # register 3: drive communications timeout, 10 ms units
COIL_EEPROM = 64  # coil 65: write memory storage type
TEXT_READ_INDEX = 0x0400  # "Text Blocks": IND before a text read
TEXT_WRITE_INDEX = 0x0500  # example 6: "Write IND with 0500 to perform a text write"


# Every parameter known of each model, with its source (:mod:`.vlt_parameters`).
PARAMETERS: Dict[int, ParameterSpec] = {
    number: spec for table in VLT_PARAMETERS.values() for number, spec in table.items()}

# Readouts per model: the option card manual (a VLT 6000 manual) reads motor current from
# par. 514; the VLT 5000 FC-protocol example reads it from par. 520. Overridable per device
# with the ``current_parameter`` setting.
READOUTS: Dict[str, Dict[str, int]] = {
    'vlt5000': {'motor_current': 520, 'alarm_word': 538, 'warning_word': 540,
                'extended_status': 541},
    'vlt6000': {'motor_current': 514, 'alarm_word': 538, 'warning_word': 540,
                'extended_status': 541},
}

# "Exception Codes": the option card puts the drive's FC-protocol error code into the
# exception reply, so these codes replace the Modbus standard's meanings.
EXCEPTIONS: Dict[int, str] = {
    0: 'the parameter number does not exist',
    1: 'there is no write access to the parameter',
    2: 'the data value exceeds the parameter limits',
    3: 'the used sub-index does not exist',
    4: 'the parameter is not of the array type',
    5: 'the data type does not match the parameter called',
    17: 'data change in the parameter is not possible in the present mode of the drive '
        '(some parameters can only be changed when the motor has stopped)',
    130: 'there is no bus access to the parameter called',
    131: 'data change is not possible because factory setup is selected',
    255: 'message timeout (the option card got no answer from the drive: check the ribbon '
         'cables and par. 500-502)',
    64: 'invalid data address',
    65: 'invalid message length',
    66: 'invalid data length',
    67: 'invalid function code (the card supports 01, 03, 05, 06, 0F and 10)',
}


def explain_exception(code: int, detail: Optional[int] = None) -> str:
    """Return technician text for an exception code of the option card."""
    text = EXCEPTIONS.get(code, 'exception code not in the option card manual')
    return f'{text}, Modbus exception {code:02d}'


DATA = DriveFamilyData(
    name=FAMILY, models=MODELS, parameters=PARAMETERS, readouts=READOUTS,
    conversion_factors=VLT_CONVERSION_FACTORS, alarm_bits={}, warning_bits={},
    extended_status_bits={}, explain_exception=explain_exception,
    index_register=REGISTER_IND, eeprom_coil=COIL_EEPROM,
    timeout_register=REGISTER_MODBUS_TIMEOUT, drive_link_timeout_register=REGISTER_DRIVE_TIMEOUT,
    text_read_index=TEXT_READ_INDEX, text_write_index=TEXT_WRITE_INDEX,
    model_parameters=VLT_PARAMETERS)

DRIVE_LINK_TIMEOUT = Setting(
    'drive_link_timeout', float, 0.0,
    "VLT option card: register 3, the card's drive communications timeout in seconds, "
    'written when the drive comes online; 0 = leave it', low=0.0, high=655.35)

ENTRY = Family(
    name=FAMILY, description='VLT 5000 / VLT 6000 HVAC with the Modbus RTU option card',
    models=MODELS, address_range=ADDRESS_RANGE,
    protocols=('modbus_rtu', 'modbus_tcp', 'rtu_over_tcp', 'fc_protocol'),
    settings=(COMMS_TIMEOUT, DRIVE_LINK_TIMEOUT, CURRENT_PARAMETER),
    make_profile=make_drive_profile(DATA), reference=True)
