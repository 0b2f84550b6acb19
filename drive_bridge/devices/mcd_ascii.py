"""
MCD soft starters over AP ASCII: the MCD Modbus Module in AP ASCII mode, and the MCD 3000.

The states, status bits and the module's trip names are the MCD family's tables
(:mod:`drive_bridge.devices.mcd`); only the transactions and the MCD 3000's own trip table
differ. Sources: manual ``000_b701c31669ff8873.txt`` section 10 and ``protocols.md``.
"""

from typing import Any, Dict, Optional, Sequence

from drive_bridge.devices import mcd
from drive_bridge.devices.contracts import (
    CommandPlan, ControlView, DeviceReading, ParameterOptions, ParameterPlan, PollCycle,
    PollShape, PollStep)
from drive_bridge.errors import CommandRefused, ProtocolError
from drive_bridge.protocol import ap_ascii
from drive_bridge.protocol.commands import Command
from drive_bridge.protocol.requests import AsciiCommand, AsciiRequest
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

    commands = frozenset(ap_ascii.COMMANDS)

    def poll_shape(self) -> PollShape:
        """Status, trip code, current and temperature: one exchange each."""
        return PollShape(transactions=4)

    def poll(self, control: ControlView, now_s: float) -> PollCycle:
        """
        Ask for status, and current and temperature where the model has them.

        The trip code (C18) is asked for when the status shows a trip, and otherwise only
        when the slow readouts are due (each request is an exchange of its own).
        """
        replies = {'status': (yield PollStep(AsciiRequest(*ap_ascii.REQUESTS['status']),
                                             stamps=True))}
        if not isinstance(replies['status'], int):
            raise ProtocolError('no status in the reply')
        tripped = mcd.STATE_CODES.get(bits(replies['status'], 0, 3)) == 'tripped'
        keys = ['trip_code'] if tripped or self.slow_readouts.due(now_s) else []
        if self.features.has_current:
            keys.append('motor_current')
        if self.features.has_temperature:
            keys.append('motor_temperature')
        for key in keys:
            replies[key] = yield PollStep(AsciiRequest(*ap_ascii.REQUESTS[key]))
        replies.setdefault('trip_code', mcd.NO_TRIP)  # not tripped: no trip code to ask
        return self.decode_replies(replies)

    def decode_replies(self, values: Dict[str, object]) -> DeviceReading:
        """Decode the replies of one poll, by request name."""
        if not isinstance(values.get('status'), int) or \
                not isinstance(values.get('trip_code'), int):
            raise ProtocolError('status or trip code missing from the replies')
        status = values['status']
        trip_code, name = self.trip(values['trip_code'])
        reading = mcd.starter_reading(self.features, status, trip_code, name, 'in C22')
        if 'motor_current' in values:
            reading.motor_current_a = float(values['motor_current']) * self.current_scale
        if 'motor_temperature' in values:
            reading.motor_temperature_pct = float(values['motor_temperature'])
        reading.details.update({
            'model': self.resolved_model or 'auto (AP ASCII cannot report the model)',
            'protocol': 'AP ASCII',
            'positive_phase_rotation': str(bit(status, mcd.STATUS_BIT_PHASE_SEQUENCE)),
            'communications_device_fault': str(bit(status, STATUS_BIT_COMMS_DEVICE_FAULT)),
            'trip_code_reply': str(values['trip_code']),
        })
        if bit(status, STATUS_BIT_COMMS_DEVICE_FAULT):
            reading.fault = 'communications device fault (C22 bit 7): the module or Remote ' \
                'Operator cannot talk to the starter' + (f'; {reading.fault}' if reading.fault
                                                         else '')
        return reading

    def trip(self, code: int) -> tuple:
        """Return (topic trip code, name) of a C18 reply; MCD 3000 uses its own table."""
        if code == mcd.NO_TRIP:
            return 0, ''
        if self.resolved_model == 'mcd3000':
            name = MCD3000_TRIP_CODES.get(code, f'unknown MCD 3000 trip code {code}')
            return (MCD3000_SHORTED_SCR_TOPIC_CODE if code == 0 else code), name
        return code, mcd.trip_name(code, self.resolved_model or '')

    def command_plan(self, command: Command, control: ControlView) -> CommandPlan:
        """Return the AP ASCII command of ``command`` (B10 start ... B18 forced comms trip)."""
        code = ap_ascii.COMMANDS.get(command)
        if code is None:
            raise CommandRefused(f'MCD starters have no {command.value} command (allowed: '
                                 'start, stop, quick_stop, reset; forced_comms_trip from '
                                 'Python)')
        if command is Command.FORCED_COMMS_TRIP and self.resolved_model == 'mcd3000':
            raise CommandRefused('the forced communication trip (B18) is a Modbus Module '
                                 'command: the MCD 3000 has none')
        return CommandPlan(command, (AsciiCommand(code),))

    def parameter_plan(self, number: int, value: Any = None,
                       options: ParameterOptions = ParameterOptions()) -> ParameterPlan:
        """Refuse: AP ASCII has no parameter access."""
        raise CommandRefused('AP ASCII has no parameter access: use Modbus RTU for parameters')

    def parameter_numbers(self) -> Sequence[int]:
        """Return nothing: AP ASCII has no parameter access."""
        return ()

    def explain_exception(self, code: int, detail: Optional[int] = None) -> str:
        """Return technician text for a BEL (the only refusal AP ASCII has)."""
        if code == ap_ascii.BEL:
            return ('refused by the starter (BEL): network control may be disabled (Hand On '
                    'mode or MCD 500 par. 3-2), or the MCD 3000 does not accept it now')
        return f'AP ASCII error {code}'
