"""
MCD 200 with the Profibus Module, through a DP-master gateway (family ``lvsg``). No I/O.

The gateway exposes the slave's LVSG process image as Modbus registers: the input bytes
(status, and with the extended module the operating-parameter answer) and the output bytes
(control, and the parameter request). Where they sit, and which byte of a register comes
first, is the gateway's configuration, so it is the device's configuration here. Tables:
:mod:`drive_bridge.protocol.lvsg` (manual ``002_8ae547a04c1e19a0.txt``).

The bridge reads the output image back from the gateway at first contact. Until a command
is in force it writes no control bits, except to clear a Fwd Run that could start a starter
that is not on (see :meth:`LvsgProfile.poll`); the extended module's parameter request (1,
2, 3, 4 in turn) is written every poll unless the device is monitor-only. Which command is
in force is the bus's motor-state owner's to decide.
"""

from dataclasses import replace
from typing import Any, Dict, FrozenSet, Mapping, Optional

from drive_bridge.devices.contracts import (
    CommandPlan, ControlView, CyclicControl, DeviceProfile, DeviceReading, Family, Freshness,
    PollCycle, PollShape, PollStep, SlowReadouts, TRIP_CODE_UNKNOWN)
from drive_bridge.devices.lvsg_image import GatewayImage
from drive_bridge.errors import CommandRefused, ConfigError, ModelMismatch, ProtocolError
from drive_bridge.protocol import lvsg
from drive_bridge.protocol.commands import Command
from drive_bridge.protocol.lvsg import Control
from drive_bridge.protocol.requests import Request
from drive_bridge.protocol.words import bit
from drive_bridge.settings import Setting

FAMILY = 'lvsg'
MODELS = ('auto', 'mcd201', 'mcd202')
ADDRESS_RANGE = (1, 247)  # the gateway's Modbus unit id; the Profibus address is the gateway's
MODULES = ('basic', 'extended')
BYTE_ORDERS = ('big', 'little')
GATEWAY_EXCEPTIONS: Dict[int, str] = {
    1: 'illegal function (the gateway does not support this function code)',
    2: 'illegal data address (check gateway_input_register and gateway_output_register '
       'against the gateway mapping)',
    3: 'illegal data value',
    4: 'gateway failure',
}


def status_word(status: lvsg.Status) -> int:
    """Return the status bytes as the contract's status word (byte 1 high)."""
    data = lvsg.encode_status(status.ready, status.on, status.fault, status.ramping,
                              status.current_raw)
    return data[1] << 8 | data[0]


def fill_trip(reading: DeviceReading, trip_code: Optional[int], extended: bool) -> None:
    """Name a trip by a trip code read since it began (None: none; an older one is another's)."""
    if trip_code not in (None, lvsg.NO_TRIP):
        reading.trip_code, reading.trip_name = trip_code, lvsg.trip_name(trip_code)
    else:
        reading.trip_code = TRIP_CODE_UNKNOWN
        reading.trip_name = 'tripped (trip code not known: ' + (
            'not read yet)' if extended else 'read it in the diagnostic telegram)')
    reading.fault = f'tripped: {reading.trip_name}'


class OperatingParameters:
    """
    What was read of one MCD 200 and when: the operating parameters and the fast signals.

    Current and temperature (parameters 3, 4) take turns every poll; product and state (1,
    2) come in when the slow readouts are due and until each was read once. Each answer is
    kept with the poll that read it (:class:`Freshness`). The status bits and the command in
    force when they were read are noted every poll (:meth:`note`): the state (2) counts only
    while it is current, read with or after the status bits' newest change and after the
    command's (a byte read in the poll a command went out may not show it yet), and it is
    asked for next whenever it is not current (after a trip: until it names the trip).
    """

    def __init__(self, slow_readouts: SlowReadouts):
        self.slow_readouts = slow_readouts
        self.request = lvsg.PARAMETER_PRODUCT
        self.read = Freshness()
        self.status_since = 0  # the poll since which the status bits have their values
        self.state_since = 1  # the first poll whose state byte is current
        self.run_dropped = False  # the bridge's Fwd Run went off after the status changed
        self._slow_turn = 0

    def forget(self) -> None:
        """Forget every answer and signal (offline)."""
        self.read.forget()
        self.request = lvsg.PARAMETER_PRODUCT

    def note(self, status: lvsg.Status, steady: Optional[Command]) -> None:
        """Note the status bits just read and the command in force when they were read."""
        read = self.read
        self.status_since = read.hold('status', (status.ready, status.on, status.fault,
                                                 status.ramping))
        self.state_since = max(self.status_since, read.hold('command', steady) + 1)
        run = steady is Command.START
        run_since = read.hold('run', run)  # noted every poll, running or not
        self.run_dropped = not run and run_since > self.status_since

    def state_parameter(self) -> Optional[int]:
        """Return parameter 2 (trip code, state byte) if it is current, else None."""
        return self.read.current(lvsg.PARAMETER_STATE, self.state_since)

    def take_answer(self, status: lvsg.Status, now_s: float) -> None:
        """Keep the answer to the request in force; choose the next (poll begun at ``now_s``)."""
        if status.parameter == self.request and not status.invalid_parameter:
            self.read.take(self.request, status.value)
            self.request = self._next_request(now_s)
        if status.invalid_parameter and status.parameter == lvsg.PARAMETER_STATE:
            return  # refused: asking again would starve the others
        state = self.state_parameter()  # None: not current
        outdated = state is None and self.read.read_in(lvsg.PARAMETER_STATE) is not None
        trip_unknown = status.fault and (state is None or state >> 8 == lvsg.NO_TRIP)
        if outdated or trip_unknown:
            self.request = lvsg.PARAMETER_STATE

    def reported_model(self) -> Optional[str]:
        """
        Return the model the answers tell (None: not read yet).

        An MCD 201 by its placeholders (current 2222, temperature 111), else an MCD 202;
        raise ModelMismatch for a product type that is not an MCD 200.
        """
        product = self.read.get(lvsg.PARAMETER_PRODUCT)
        if product is None:
            return None
        if lvsg.product_type(product) != lvsg.MCD200_PRODUCT_TYPE:
            raise ModelMismatch(
                f'model mismatch: the slave reports product type {lvsg.product_type(product)} '
                f'(operating parameter 1), not 4 = MCD 200; check the gateway mapping')
        current = self.read.get(lvsg.PARAMETER_CURRENT)
        temperature = self.read.get(lvsg.PARAMETER_TEMPERATURE)
        if current is None or temperature is None:
            return None
        is_201 = current == lvsg.MCD201_CURRENT_PLACEHOLDER and \
            temperature & 0xFF == lvsg.MCD201_TEMPERATURE_PLACEHOLDER
        return 'mcd201' if is_201 else 'mcd202'

    def _next_request(self, now_s: float) -> int:
        slow = (lvsg.PARAMETER_PRODUCT, lvsg.PARAMETER_STATE)
        unread = [number for number in slow if self.read.read_in(number) is None]
        if unread:
            return unread[0]
        if self.request == lvsg.PARAMETER_CURRENT:
            return lvsg.PARAMETER_TEMPERATURE
        if self.request == lvsg.PARAMETER_TEMPERATURE and self.slow_readouts.due(now_s):
            self._slow_turn = (self._slow_turn + 1) % len(slow)
            return slow[self._slow_turn]
        return lvsg.PARAMETER_CURRENT


class StarterState:
    """
    The contract's state of an MCD 200, decided by the freshest information.

    The status bits (Ready, On, Fault, Ramping) are read every poll, but cannot tell a start
    ramp from a stop ramp, nor a restart delay from another not-ready. The MCD 200 state of
    parameter 2 can, but it is read in turn: it refines the status bits only while current
    (read since their newest change and the command's). Otherwise a ramp's direction comes
    from what happened last: the bridge's own Fwd Run dropped after the ramp began (a soft
    stop), else the state before the ramp (a starter that was not running is starting,
    whoever started it); at first contact, the Fwd Run the gateway holds.
    """

    def __init__(self) -> None:
        self.last = ''  # the state last decided ('' before first contact)

    def decide(self, status: lvsg.Status, state_byte: Optional[int], run_dropped: bool,
               gateway_fwd_run: bool) -> str:
        """
        Return the state and remember it.

        ``state_byte``: parameter 2's low byte if current, else None. ``run_dropped``: the
        bridge's Fwd Run went off after the status bits took their present values.
        """
        self.last = self._decide(status, state_byte, run_dropped, gateway_fwd_run)
        return self.last

    def _decide(self, status: lvsg.Status, state_byte: Optional[int], run_dropped: bool,
                gateway_fwd_run: bool) -> str:
        known = lvsg.MCD200_STATES.get(state_byte & 0x0F) if state_byte is not None else None
        if status.fault:
            return 'tripped'
        if status.on and status.ramping:
            if known in ('starting', 'stopping'):
                return known
            return 'stopping' if run_dropped else self._ramp_direction(gateway_fwd_run)
        if status.on:
            return 'running'
        if status.ready:
            return 'ready'
        return known if known in ('restart_delay', 'unknown') else 'not_ready'

    def _ramp_direction(self, gateway_fwd_run: bool) -> str:
        if self.last in ('starting', 'stopping'):
            return self.last
        if self.last == 'running':
            return 'stopping'
        if self.last:
            return 'starting'
        return 'starting' if gateway_fwd_run else 'stopping'


class LvsgProfile(DeviceProfile, CyclicControl):
    """
    Poll cycle, decode and commands of one MCD 200 behind a Profibus gateway.

    The process image travels through a :class:`~drive_bridge.devices.lvsg_image.GatewayImage`
    (``gateway``: where the bytes sit, the control bits the gateway holds); the operating
    parameters are :class:`OperatingParameters`, the starter's state :class:`StarterState`.
    """

    family = FAMILY
    commands = frozenset({Command.START, Command.STOP, Command.QUICK_STOP, Command.RESET})

    def __init__(self, model: str = 'auto', current_scale: float = 1.0,
                 input_register: int = 0, output_register: int = 0,
                 byte_order: str = 'big', module: str = 'extended',
                 slow_readouts: Optional[SlowReadouts] = None):
        if model not in MODELS:
            raise ConfigError(f'unknown lvsg model {model!r}: allowed {", ".join(MODELS)}')
        if module not in MODULES or byte_order not in BYTE_ORDERS:
            raise ConfigError(f'lvsg module must be one of {MODULES}, byte order one of '
                              f'{BYTE_ORDERS}')
        super().__init__(model)
        self.current_scale = current_scale
        self.extended = module == 'extended'
        self.gateway = GatewayImage(input_register, output_register, byte_order, self.extended)
        self.operating = OperatingParameters(slow_readouts or SlowReadouts(0.0))
        self.starter = StarterState()
        self.hazard = ''

    @property
    def reading_fields(self) -> FrozenSet[str]:
        """Return current and temperature: the extended module reads them (not an MCD 201)."""
        if not self.extended or self.resolved_model == 'mcd201':
            return frozenset()
        return frozenset({'motor_current', 'motor_temperature'})

    def on_offline(self) -> None:
        """Forget the image and the answers: after a reconnect the image is read again."""
        self.gateway.forget()
        self.operating.forget()
        self.starter = StarterState()
        self.hazard = ''

    # -- the image --------------------------------------------------------------------------
    @staticmethod
    def control_for(steady: Command) -> Control:
        """Return the control bits that carry ``steady`` (Fwd Run only for a start)."""
        if steady is Command.START:
            return Control(fwd_run=True)
        if steady is Command.QUICK_STOP:
            return Control(quick_stop=True)
        return Control()

    def image_write(self, control: Control) -> Request:
        """Return the write of the whole output image carrying ``control``."""
        return self.gateway.write(control, self.operating.request)

    def poll_shape(self) -> PollShape:
        """Return the image (or request) write, the input read, Fwd Run cleared; read-back."""
        return PollShape(transactions=3, writes=1, online=1)

    def describe_control(self, control: ControlView) -> str:
        """Return the control bits the gateway holds, in words."""
        return self.gateway.describe(control.steady)

    # -- polling ------------------------------------------------------------------------
    def poll(self, control: ControlView, now_s: float) -> PollCycle:
        """
        One poll: read back or write the output image, read the input image.

        At first contact the output image is read back. While a command is in force the
        whole image is written each poll (the keepalive); before that, the extended module's
        parameter request alone (never the control bits). A Fwd Run held in the gateway for
        a starter that is not on would start it (manual 002: leaving Clear mode with Fwd Run
        set restarts the motor): the image is written back with Fwd Run clear, the one write
        allowed before a command, or reported as a hazard when nothing may be written.
        """
        self.operating.read.begin_poll()
        gateway = self.gateway
        first_contact = gateway.image is None
        if first_contact:
            gateway.adopt((yield PollStep(gateway.read_back(), optional=True)))
        steady = control.steady
        if steady is not None and control.writes_allowed:
            gateway.image = self.control_for(steady)
            yield PollStep(self.image_write(gateway.image), optional=True, retry=False)
        elif self.extended and control.writes_allowed and not first_contact:
            # Not at first contact: a Fwd Run found in the gateway is dealt with first.
            yield PollStep(gateway.request_write(self.operating.request), optional=True,
                           retry=False)
        registers = yield PollStep(gateway.read_input(), stamps=True)
        if not isinstance(registers, list):
            raise ProtocolError('input image missing from the replies')
        status = gateway.decode_input(registers)
        self.operating.note(status, control.steady)  # in force when the status was read
        if self.extended:
            self.operating.take_answer(status, now_s)
        if control.steady is None:  # asked again: a command may have gone out meanwhile
            yield from self._clear_unasked_fwd_run(status, control)
        self._resolve_model()
        return self._reading(status)

    def _clear_unasked_fwd_run(self, status: lvsg.Status, control: ControlView):
        """Write Fwd Run clear if the gateway holds it for a starter that is not on."""
        image = self.gateway.image
        if image is None or not image.fwd_run or status.on:
            self.hazard = ''
            return
        if not control.writes_allowed:
            self.hazard = ('HAZARD: the gateway holds Fwd Run for a starter that is not on: '
                           'it starts when the DP master leaves Clear mode or the trip is '
                           'reset; nothing written (monitor only): clear Fwd Run at the '
                           'master that set it')
            return
        cleared = replace(image, fwd_run=False, reset=False)
        result = yield PollStep(self.image_write(cleared), optional=True, retry=False)
        if isinstance(result, Exception):
            self.hazard = ('HAZARD: the gateway holds Fwd Run for a starter that is not on and '
                           f'clearing it failed ({result}); it will be tried again')
            return
        self.gateway.image = cleared
        self.hazard = ''

    def _resolve_model(self) -> None:
        reported = self.operating.reported_model()
        if reported is None:
            return
        if self.configured_model == 'auto':
            self.resolved_model = reported
        elif reported != self.configured_model and reported == 'mcd201':
            raise ModelMismatch(f'model mismatch: configured {self.configured_model} but the '
                                'slave reads current 2222 and temperature 111, as an MCD 201')

    def _reading(self, status: lvsg.Status) -> DeviceReading:
        operating = self.operating
        state_value = operating.state_parameter()  # None: not current
        trip_code, state_byte = lvsg.split_state_parameter(state_value) \
            if state_value is not None else (None, None)
        state = self.starter.decide(status, state_byte, operating.run_dropped,
                                    self.gateway.fwd_run)
        reading = DeviceReading(state=state, status_word=status_word(status))
        if status.fault:
            fill_trip(reading, trip_code, self.extended)
        if self.resolved_model != 'mcd201':
            current = operating.read.get(lvsg.PARAMETER_CURRENT)
            if current is not None:
                reading.motor_current_a = float(current) * self.current_scale
            temperature = operating.read.get(lvsg.PARAMETER_TEMPERATURE)
            if temperature is not None:
                reading.motor_temperature_pct = float(temperature & 0xFF)
        reading.details = self._details(status, state_byte)
        if state_byte is not None and bit(state_byte, lvsg.STATE_BIT_COMMS_FAILURE):
            reading.fault = 'communication failure between the Profibus Module and the MCD 200'
        if state_byte is not None and bit(state_byte, lvsg.STATE_BIT_CURRENT_ABOVE_FLC):
            reading.warnings.append('motor current exceeds FLC')
        if self.hazard:
            reading.fault = self.hazard + (f'; {reading.fault}' if reading.fault else '')
        return reading

    def _details(self, status: lvsg.Status, state_byte: Optional[int]) -> Dict[str, str]:
        details = {
            'model': self.resolved_model or 'auto (waiting for operating parameters)',
            'module': 'extended' if self.extended else 'basic',
            'ready': str(status.ready), 'on': str(status.on), 'fault': str(status.fault),
            'ramping': str(status.ramping),
            'motor_current_pct_flc': f'{status.current_pct_flc:.0f}',
            'gateway_fwd_run': str(self.gateway.fwd_run),
            'gateway_quick_stop': str(self.gateway.quick_stop),
        }
        product = self.operating.read.get(lvsg.PARAMETER_PRODUCT)
        if product is not None:
            details['product_type'] = str(lvsg.product_type(product))
            details['software_version'] = str(product & 0xFF)
        if state_byte is not None:
            details['mcd200_state'] = str(state_byte & 0x0F)
            details['positive_phase_rotation'] = str(bit(state_byte,
                                                         lvsg.STATE_BIT_POSITIVE_ROTATION))
            details['rotation_validated'] = str(bit(state_byte,
                                                    lvsg.STATE_BIT_ROTATION_VALIDATED))
        return details

    # -- commands -----------------------------------------------------------------------
    def command_plan(self, command: Command, control: ControlView) -> CommandPlan:
        """Return the output-image writes of ``command``."""
        base = self.gateway.image or Control()
        if command is Command.START:
            steps = [Control(fwd_run=True)]
        elif command is Command.STOP:
            steps = [Control()]
        elif command is Command.QUICK_STOP:  # Quick Stop set before Fwd Run is cleared
            # Fwd Run stays as it is in force (a rising Fwd Run would start the starter):
            # the bus's run command if it has one, else the image read back.
            fwd_run = control.steady is Command.START if control.steady is not None \
                else base.fwd_run
            steps = [Control(fwd_run=fwd_run, quick_stop=True), Control(quick_stop=True)]
        elif command is Command.RESET:  # a pulse on bit 3, with Fwd Run clear: never a restart
            steps = [Control(reset=True, quick_stop=base.quick_stop),
                     Control(quick_stop=base.quick_stop)]
        else:
            raise CommandRefused(f'MCD 200 starters have no {command.value} command (allowed: '
                                 'start, stop, quick_stop, reset)')
        return CommandPlan(command, tuple(self.image_write(step) for step in steps))

    def explain_exception(self, code: int, detail: Optional[int] = None) -> str:
        """Return technician text for a Modbus exception from the gateway."""
        return f'{GATEWAY_EXCEPTIONS.get(code, "gateway exception")}, Modbus exception ' \
               f'{code:02d}'


SETTINGS = (
    Setting('gateway_input_register', int, None,
            "lvsg: frame address of the first register holding the slave's input bytes "
            '(status) in the gateway', low=0, high=65535),
    Setting('gateway_output_register', int, None,
            "lvsg: frame address of the first register holding the slave's output bytes "
            '(control) in the gateway', low=0, high=65535),
    Setting('gateway_byte_order', str, 'big',
            'lvsg: big = the first process byte is the high byte of a register',
            choices=BYTE_ORDERS),
    Setting('lvsg_module', str, 'extended',
            'lvsg: the GSD module configured in the DP master: basic or extended',
            choices=MODULES),
)


def make_profile(model: str, protocol: str, options: Mapping[str, Any]) -> LvsgProfile:
    """Return the profile of an MCD 200 behind a gateway from validated options."""
    return LvsgProfile(model, options.get('current_scale', 1.0),
                       options['gateway_input_register'], options['gateway_output_register'],
                       options.get('gateway_byte_order', 'big'),
                       options.get('lvsg_module', 'extended'),
                       SlowReadouts(options.get('readout_period', 0.0)))


ENTRY = Family(
    name=FAMILY, description='MCD 200 with the Profibus Module, through a DP-master gateway '
    'that maps the LVSG process image to Modbus registers',
    models=MODELS, address_range=ADDRESS_RANGE,
    protocols=('modbus_tcp', 'rtu_over_tcp', 'modbus_rtu'), settings=SETTINGS,
    make_profile=make_profile)
