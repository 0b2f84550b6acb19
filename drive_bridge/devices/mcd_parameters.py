"""
MCD soft starter parameter names as data, keyed by each manual's own designation.

Sources:

- manual 000 (``shared/manuals/000_b701c31669ff8873.txt``, MCD Modbus Module 175G9000):
  section 6 (register 40009 on: "Parameter 1-A (Motor FLC)" to MCD 500 "Par. 20-6
  (Pedestal Detect)" and MCD 3000 "Par. 60 (Min Run Frequency)"; note 2: the first product
  parameter is register 40009, the last 40008 + the number of parameters; the N.B.: option
  numbers over the module start at 0, one less than on the LCP, e.g. 2-1 Phase Sequence),
  section 8.1 (worked examples: read "Parameter 1, Motor FLC (Parameter 1-1)" = 100 A at
  40009; write "Parameter 4, Current Limit (Parameter 1-4)" = 400 % FLC at 40012), section 9
  (3-2 Comms in Remote), section 11 (Remote Operator parameters 1-9, complete; MCD 3000
  parameters 20 and 24);
- a public copy of the MCD 500 Operating Instructions (manualarchiveguide.com, Danfoss
  MCD 500 operating manual, section 5.3: "parameter 1-5 Initial current", "parameter 1-4
  Current limit"; section 5.1: "Par. 1-1 Motor FLC ... Primary Motor Set").

Register mapping: the module gives each product parameter a register in the order of the
product's parameter list ("Parameter N" is register 40008 + N). Only N for 1-1 (1) and 1-4
(4) is stated; 1-5 as 5 is inferred from that order. The rest of the MCD 500 list and its
order (the MCD 500 Operating Instructions parameter list) could not be found in the stores
searched, so ``serial_number`` stays None (open) for the other MCD 500 entries; the CLI can
still read and write by register as today (:data:`drive_bridge.devices.mcd.MODEL_FEATURES`
max_parameter). MCD 3000 parameters are numbered 1-60 and par. 60 is the last, so par. N is
register 40008 + N (inferred from note 2). MCD 200 has no parameter registers.

All module registers are 16 bits (functions 03 and 06), values raw: a McdParameter's
:meth:`spec` gives a uint16 ParameterSpec for :func:`~drive_bridge.devices.parameters.
check_value`.
"""

from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Dict, Mapping, Optional, Tuple

from drive_bridge.devices.parameters import ParameterSpec

FIRST_PARAMETER_REGISTER = 40009  # manual 000 section 6, note 2
M0 = 'manual 000'
MCD500_OI = 'MCD 500 Operating Instructions (public copy, manualarchiveguide.com)'


@dataclass(frozen=True)
class McdParameter:
    """One soft starter parameter, keyed by the designation its own manual uses."""

    model: str  # 'mcd500', 'mcd3000', 'remote_operator'
    designation: str  # the manual's: '1-1' (MCD 500), '60' (MCD 3000), '6' (Remote Operator)
    name: str
    source: str
    serial_number: Optional[int] = None  # manual 000's "Parameter N": register 40008 + N
    unit: str = ''
    minimum: Optional[int] = None
    maximum: Optional[int] = None
    options: Optional[Mapping[int, str]] = field(default=None, hash=False)  # as on the bus
    options_partial: bool = False
    default: Optional[int] = None
    setting: bool = True
    aliases: Tuple[str, ...] = ()  # other editions' designations ('1A' for '1-1')
    inferred: Tuple[str, ...] = ()
    # Keeps the starter on the network (ParameterSpec.serial_line): read-only from ROS, never
    # written by a restore.
    serial_line: bool = False

    def __post_init__(self):
        if self.options is not None:
            object.__setattr__(self, 'options', MappingProxyType(dict(self.options)))

    @property
    def register(self) -> Optional[int]:
        """Return the module's register number from 40009 on; None where the mapping is open."""
        if self.serial_number is None:
            return None
        return FIRST_PARAMETER_REGISTER - 1 + self.serial_number

    def spec(self) -> ParameterSpec:
        """Return a uint16 ParameterSpec of the raw value (number: serial number)."""
        return ParameterSpec(
            self.serial_number or 0, self.name, 'uint16', 0, source=self.source,
            minimum=self.minimum, maximum=self.maximum, options=self.options,
            options_partial=self.options_partial, unit=self.unit, setting=self.setting,
            default=self.default, label=self.designation, serial_line=self.serial_line,
            inferred=tuple(name for name in self.inferred if name != 'serial_number'))


MCD500: Tuple[McdParameter, ...] = (
    McdParameter('mcd500', '1-1', 'Motor FLC', M0 + ' sections 6 and 8.1 (100 A reads 100); '
                 'name also ' + MCD500_OI + ' 5.1', serial_number=1, unit='A',
                 aliases=('1A',)),
    McdParameter('mcd500', '1-4', 'Current Limit', M0 + ' section 8.1 (400 % FLC writes 400); '
                 + MCD500_OI + ' 5.3', serial_number=4, unit='% FLC'),
    McdParameter('mcd500', '1-5', 'Initial Current', MCD500_OI + ' 5.3 (current ramp start '
                 'level); unit as 1-4 and serial number 5 from the list order: inferred',
                 serial_number=5, unit='% FLC', inferred=('serial_number', 'unit')),
    McdParameter('mcd500', '2-1', 'Phase Sequence', M0 + ' section 6 N.B.: options 1-3 on '
                 'the LCP are 0-2 over the module', minimum=0, maximum=2),
    McdParameter('mcd500', '3-2', 'Comms in Remote', M0 + ' sections 4 and 9: when set to '
                 'disable, the starter refuses start/stop over the network (error 09)'),
    McdParameter('mcd500', '20-6', 'Pedestal Detect', M0 + ' section 6: the last MCD 500 '
                 'parameter register (write range 40009-40599, section 8)'),
)

MCD3000: Tuple[McdParameter, ...] = (
    McdParameter('mcd3000', '20', '(local/remote control)', M0 + ' section 11.7: "to operate '
                 'correctly on the network, the MCD 3000 must be set for local operation only '
                 '(i.e. set Parameter 20 = 2)": another value takes the starter, and its stop, '
                 'off the network', serial_number=20,
                 options={2: 'Local operation only'}, options_partial=True,
                 inferred=('serial_number', 'name'), serial_line=True),
    McdParameter('mcd3000', '24', 'Serial Timeout', M0 + ' section 11.7 (starter to Remote '
                 'Operator link)', serial_number=24, inferred=('serial_number',)),
    McdParameter('mcd3000', '60', 'Min Run Frequency', M0 + ' section 6: the last MCD 3000 '
                 'parameter register', serial_number=60, inferred=('serial_number',)),
)

_RO = M0 + ' section 11.8.2 (set on the Remote Operator keypad, not over the bus)'
REMOTE_OPERATOR: Tuple[McdParameter, ...] = (
    McdParameter('remote_operator', '1', 'RS485 network baud rate', _RO,
                 options={2: '2400 baud', 3: '4800 baud', 4: '9600 baud', 5: '19200 baud',
                          6: '38400 baud'}, default=4),
    McdParameter('remote_operator', '2', 'RS485 network satellite address', _RO, minimum=1,
                 maximum=99, default=20),
    McdParameter('remote_operator', '3', 'RS485 network timeout', _RO, unit='s', minimum=0,
                 maximum=100, default=0),
    McdParameter('remote_operator', '4', 'RS485 network protocol', _RO,
                 options={1: 'AP ASCII', 2: 'Modbus RTU'}, default=1),
    McdParameter('remote_operator', '5', 'Modbus protocol parity', _RO,
                 options={0: 'No parity', 1: 'Odd parity', 2: 'Even parity',
                          3: '10-bit transmission'}, default=0),
    McdParameter('remote_operator', '6', 'Motor FLC', _RO, unit='A', minimum=1, maximum=2868,
                 default=10),
    McdParameter('remote_operator', '7', 'Analog output 4 mA offset', _RO, unit='%',
                 minimum=80, maximum=120, default=100),
    McdParameter('remote_operator', '8', 'Start, Stop, Quick stop function disable', _RO,
                 options={0: 'Remote Operator and network enabled',
                          1: 'Remote Operator enabled, network disabled',
                          2: 'Remote Operator disabled, network enabled',
                          3: 'Remote Operator and network disabled'}, default=0),
    McdParameter('remote_operator', '9', 'Current / 10', _RO,
                 options={0: 'Off (MCD5-0084B to MCD5-1600C)',
                          1: 'On (MCD5-0021B to MCD5-0068B)'}, default=0),
)

MCD_PARAMETERS: Dict[str, Dict[str, McdParameter]] = {
    table[0].model: {entry.designation: entry for entry in table}
    for table in (MCD500, MCD3000, REMOTE_OPERATOR)
}


def by_register(model: str) -> Dict[int, McdParameter]:
    """Return register -> entry for the entries of ``model`` whose register is known."""
    return {entry.register: entry for entry in MCD_PARAMETERS.get(model, {}).values()
            if entry.register is not None}


def find(model: str, designation: str) -> Optional[McdParameter]:
    """Return the entry a designation or one of its aliases names ('1A' finds '1-1')."""
    table = MCD_PARAMETERS.get(model, {})
    wanted = designation.strip().upper()
    for entry in table.values():
        if wanted in (entry.designation.upper(),) + tuple(a.upper() for a in entry.aliases):
            return entry
    return None
