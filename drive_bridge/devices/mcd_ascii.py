"""
MCD soft starters over AP ASCII: the MCD Modbus Module in AP ASCII mode, and the MCD 3000.

The states, status bits and the module's trip names are the MCD family's tables
(:mod:`drive_bridge.devices.mcd`); only the transactions and the MCD 3000's own trip table
differ. Sources: manual ``000_b701c31669ff8873.txt`` section 10 and ``protocols.md``.
"""

from typing import Dict, List, Optional

from drive_bridge.devices import mcd
from drive_bridge.devices.base import AsciiCommand, AsciiRequest, CommandPlan, DeviceReading
from drive_bridge.errors import CommandRefused, ProtocolError
from drive_bridge.protocol import ap_ascii
from drive_bridge.protocol.words import bit, bits

# Section 10.2, C22 bit 7 (the Modbus register 40003 has no such bit).
STATUS_BIT_COMMS_DEVICE_FAULT = 7
# protocols.md: the MCD 3000's own trip codes over AP ASCII (C18); 255 = no trip. Code 0
# cannot be published as 0 (the contract's "not tripped"): it goes out as 256.
MCD3000_TRIP_CODES: Dict[int, str] = {
    0: 'Shorted SCR', 1: 'Excess start time', 2: 'Overcurrent', 3: 'Motor thermistor',
    4: 'Phase imbalance', 5: 'Supply frequency', 6: 'Phase rotation',
    7: 'Instantaneous overload', 8: 'Power circuit', 9: 'Undercurrent',
    10: 'Starter overtemperature',
}
MCD3000_SHORTED_SCR_TOPIC_CODE = 256


class McdAsciiProfile(mcd.McdProfile):
    """Requests, decode and commands of one MCD starter on AP ASCII."""

    protocol = 'ap_ascii'

    def __init__(self, model: str = 'auto', current_scale: float = 1.0):
        super().__init__(model, current_scale)
        self._keys: List[str] = []

    def poll_plan(self) -> List[AsciiRequest]:
        """Return the requests of one poll: status, trip code, and current/temperature."""
        keys = ['status', 'trip_code']
        if self.features.has_current:
            keys.append('motor_current')
        if self.features.has_temperature:
            keys.append('motor_temperature')
        self._keys = keys
        return [AsciiRequest(*ap_ascii.REQUESTS[key]) for key in keys]

    def decode(self, results: list) -> DeviceReading:
        """Decode the replies of one poll (aligned with the last plan)."""
        values = dict(zip(self._keys, results))
        if not isinstance(values.get('status'), int) or \
                not isinstance(values.get('trip_code'), int):
            raise ProtocolError('status or trip code missing from the replies')
        status = values['status']
        state_code = bits(status, 0, 3)
        state = mcd.STATE_CODES.get(state_code, 'unknown')
        trip_code, name = self.trip(values['trip_code'])
        reading = DeviceReading(state=state, status_word=status, trip_code=trip_code,
                                trip_name=name)
        if 'motor_current' in values:
            reading.motor_current_a = float(values['motor_current']) * self.current_scale
        if 'motor_temperature' in values:
            reading.motor_temperature_pct = float(values['motor_temperature'])
        reading.details = {
            'model': self.model or 'auto (AP ASCII cannot report the model)',
            'protocol': 'AP ASCII', 'state_code': str(state_code),
            'initialised': str(bit(status, mcd.STATUS_BIT_INITIALISED)),
            'current_above_flc': str(bit(status, mcd.STATUS_BIT_CURRENT_ABOVE_FLC)),
            'positive_phase_rotation': str(bit(status, mcd.STATUS_BIT_PHASE_SEQUENCE)),
            'communications_device_fault': str(bit(status, STATUS_BIT_COMMS_DEVICE_FAULT)),
            'trip_code_reply': str(values['trip_code']),
        }
        if state == 'unknown':
            reading.warnings.append(f'unknown state code {state_code} in C22')
        if bit(status, mcd.STATUS_BIT_CURRENT_ABOVE_FLC):
            reading.warnings.append('motor current exceeds FLC')
        if state == 'tripped':
            reading.fault = f'tripped: {name or "no trip code"}'
        if bit(status, STATUS_BIT_COMMS_DEVICE_FAULT):
            reading.fault = 'communications device fault (C22 bit 7): the module or Remote ' \
                'Operator cannot talk to the starter' + (f'; {reading.fault}' if reading.fault
                                                         else '')
        return reading

    def trip(self, code: int) -> tuple:
        """Return (topic trip code, name) of a C18 reply; MCD 3000 uses its own table."""
        if code == mcd.NO_TRIP:
            return 0, ''
        if self.model == 'mcd3000':
            name = MCD3000_TRIP_CODES.get(code, f'unknown MCD 3000 trip code {code}')
            return (MCD3000_SHORTED_SCR_TOPIC_CODE if code == 0 else code), name
        return code, mcd.trip_name(code, self.model or '')

    def command_plan(self, command: str) -> CommandPlan:
        """Return the AP ASCII command of ``command`` (B10 start ... B18 forced comms trip)."""
        code = ap_ascii.COMMANDS.get(command)
        if code is None:
            raise CommandRefused(f'MCD starters have no {command} command (allowed: start, '
                                 'stop, quick_stop, reset; forced_comms_trip from Python)')
        if command == 'forced_comms_trip' and self.model == 'mcd3000':
            raise CommandRefused('the forced communication trip (B18) is a Modbus Module '
                                 'command: the MCD 3000 has none')
        return CommandPlan(command, (AsciiCommand(code),))

    def parameter_plan(self, number: int, value: Optional[int] = None):
        """Refuse: AP ASCII has no parameter access."""
        raise CommandRefused('AP ASCII has no parameter access: use Modbus RTU for parameters')

    def explain_exception(self, code: int, detail: Optional[int] = None) -> str:
        """Return technician text for a BEL (the only refusal AP ASCII has)."""
        if code == ap_ascii.BEL:
            return ('refused by the starter (BEL): network control may be disabled (Hand On '
                    'mode or MCD 500 par. 3-2), or the MCD 3000 does not accept it now')
        return f'AP ASCII error {code}'
