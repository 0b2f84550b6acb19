"""
MCD 200 with the Profibus Module, through a DP-master gateway (family ``lvsg``). No I/O.

The gateway exposes the slave's LVSG process image as Modbus registers: the input bytes
(status, and with the extended module the operating-parameter answer) and the output bytes
(control, and the parameter request). Where they sit, and which byte of a register comes
first, is the gateway's configuration, so it is the device's configuration here. Tables:
:mod:`drive_bridge.protocol.lvsg` (manual ``002_8ae547a04c1e19a0.txt``).

The bridge adopts the output image it reads back from the gateway at first contact and then
owns it: the control bits stay as they were until a command arrives, except that Fwd Run is
never kept where it could start a motor nobody asked to start (see
:meth:`LvsgProfile._never_start_unasked`); the extended module's parameter request (1, 2, 3,
4 in turn) is rewritten every poll.
"""

from dataclasses import replace
from typing import Dict, List, Optional

from drive_bridge.devices.base import (
    CommandPlan, DeviceReading, PollItem, ReadRegisters, WriteRegister, WriteRegisters)
from drive_bridge.errors import CommandRefused, ConfigError, ModelMismatch, ProtocolError
from drive_bridge.protocol import lvsg
from drive_bridge.protocol.lvsg import Control
from drive_bridge.protocol.words import bit, bytes_to_registers, registers_to_bytes

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


class LvsgProfile:
    """Process image, decode and commands of one MCD 200 behind a Profibus gateway."""

    family = FAMILY

    def __init__(self, model: str = 'auto', current_scale: float = 1.0,
                 input_register: int = 0, output_register: int = 0,
                 byte_order: str = 'big', module: str = 'extended'):
        if model not in MODELS:
            raise ConfigError(f'unknown lvsg model {model!r}: allowed {", ".join(MODELS)}')
        if module not in MODULES or byte_order not in BYTE_ORDERS:
            raise ConfigError(f'lvsg module must be one of {MODULES}, byte order one of '
                              f'{BYTE_ORDERS}')
        self.configured_model = model
        self.model: Optional[str] = None if model == 'auto' else model
        self.current_scale = current_scale
        self.input_register = input_register
        self.output_register = output_register
        self.byte_order = byte_order
        self.extended = module == 'extended'
        self.input_bytes = lvsg.EXTENDED_INPUT_BYTES if self.extended else \
            lvsg.BASIC_INPUT_BYTES
        self.output_bytes = lvsg.EXTENDED_OUTPUT_BYTES if self.extended else \
            lvsg.BASIC_OUTPUT_BYTES
        self.control: Optional[Control] = None  # None: not adopted from the gateway yet
        self.commanded = False  # a command arrived since the last (re)connect
        self.request = lvsg.PARAMETER_PRODUCT
        self.values: Dict[int, int] = {}
        self._keys: List[str] = []

    @property
    def input_registers(self) -> int:
        """Return how many registers hold the input bytes."""
        return (self.input_bytes + 1) // 2

    @property
    def output_registers(self) -> int:
        """Return how many registers hold the output bytes."""
        return (self.output_bytes + 1) // 2

    def on_offline(self) -> None:
        """Forget the image and the command: after a reconnect it is adopted again."""
        self.control = None
        self.commanded = False
        self.values.clear()
        self.request = lvsg.PARAMETER_PRODUCT

    # -- polling ------------------------------------------------------------------------
    def poll_plan(self) -> List[PollItem]:
        """Return one poll: adopt or write the output image, then read the input image."""
        items = []
        if self.control is None:
            items.append(PollItem(ReadRegisters(self.output_register, self.output_registers),
                                  'output', optional=True))
        elif self.commanded:
            items.append(PollItem(self.image_write(self.control), 'write'))
        elif self.extended:  # no command yet: the parameter request alone, never control
            items.append(PollItem(self.request_write(), 'write'))
        items.append(PollItem(ReadRegisters(self.input_register, self.input_registers),
                              'input'))
        self._keys = [item.key for item in items]
        return items

    def request_write(self) -> WriteRegister:
        """Return the write of the register holding the parameter request (output byte 2)."""
        image = self.image_write(self.control or Control())  # extended: two registers
        return WriteRegister(self.output_register + 1, image.values[1])

    def image_write(self, control: Control):
        """Return the write of the whole output image carrying ``control``."""
        registers = bytes_to_registers(
            replace(control, parameter_request=self.request).encode(self.extended),
            self.byte_order)
        if len(registers) == 1:
            return WriteRegister(self.output_register, registers[0])
        return WriteRegisters(self.output_register, tuple(registers))

    def decode(self, results: list) -> DeviceReading:
        """Decode one poll into a reading."""
        by_key = dict(zip(self._keys, results))
        if 'output' in by_key:
            self._adopt(by_key['output'])
        if not isinstance(by_key.get('input'), list):
            raise ProtocolError('input image missing from the replies')
        status = lvsg.decode_status(registers_to_bytes(by_key['input'], self.input_bytes,
                                                       self.byte_order))
        if self.extended:
            self._take_answer(status)
        self._never_start_unasked(status)
        self._resolve_model()
        return self._reading(status)

    def _never_start_unasked(self, status: lvsg.Status) -> None:
        """
        Clear Fwd Run in the image the bridge rewrites when keeping it could start a motor.

        A trip ends a run command (a local reset must not restart the motor), and an adopted
        Fwd Run on a starter that is not on would start it (the gateway may hold Fwd Run
        from an earlier master, or leave Clear mode with it set).
        """
        control = self.control
        if control is None or not control.fwd_run:
            return
        if status.fault or (not self.commanded and not status.on):
            self.control = replace(control, fwd_run=False)

    def _adopt(self, result) -> None:
        if isinstance(result, list):
            self.control = Control.decode(registers_to_bytes(result, self.output_bytes,
                                                             self.byte_order))
        else:  # the gateway cannot read its outputs back: start from all bits clear
            self.control = Control()
        self.control = replace(self.control, reset=False)

    def _take_answer(self, status: lvsg.Status) -> None:
        if status.parameter == self.request and not status.invalid_parameter:
            self.values[self.request] = status.value
            index = lvsg.PARAMETERS.index(self.request)
            self.request = lvsg.PARAMETERS[(index + 1) % len(lvsg.PARAMETERS)]
        state = self.values.get(lvsg.PARAMETER_STATE)
        trip_known = state is not None and state >> 8 != lvsg.NO_TRIP
        if status.fault and not trip_known:
            self.request = lvsg.PARAMETER_STATE  # a trip: ask for the trip code next

    def _resolve_model(self) -> None:
        product = self.values.get(lvsg.PARAMETER_PRODUCT)
        if product is None:
            return
        if lvsg.product_type(product) != lvsg.MCD200_PRODUCT_TYPE:
            raise ModelMismatch(
                f'model mismatch: the slave reports product type {lvsg.product_type(product)} '
                f'(operating parameter 1), not 4 = MCD 200; check the gateway mapping')
        current = self.values.get(lvsg.PARAMETER_CURRENT)
        temperature = self.values.get(lvsg.PARAMETER_TEMPERATURE)
        if current is None or temperature is None:
            return
        is_201 = current == lvsg.MCD201_CURRENT_PLACEHOLDER and \
            temperature & 0xFF == lvsg.MCD201_TEMPERATURE_PLACEHOLDER
        reported = 'mcd201' if is_201 else 'mcd202'
        if self.configured_model == 'auto':
            self.model = reported
        elif reported != self.configured_model and is_201:
            raise ModelMismatch(f'model mismatch: configured {self.configured_model} but the '
                                'slave reads current 2222 and temperature 111, as an MCD 201')

    def _reading(self, status: lvsg.Status) -> DeviceReading:
        state_value = self.values.get(lvsg.PARAMETER_STATE)
        trip_code, state_byte = lvsg.split_state_parameter(state_value) \
            if state_value is not None else (None, None)
        reading = DeviceReading(state=self._state(status, state_byte),
                                status_word=self._status_word(status))
        if status.fault:
            if trip_code not in (None, lvsg.NO_TRIP):
                reading.trip_code, reading.trip_name = trip_code, lvsg.trip_name(trip_code)
            else:
                reading.trip_name = 'tripped (trip code not known: ' + (
                    'read it in the diagnostic telegram)' if not self.extended
                    else 'not read yet)')
            reading.fault = f'tripped: {reading.trip_name}'
        if self.model != 'mcd201':
            current = self.values.get(lvsg.PARAMETER_CURRENT)
            if current is not None:
                reading.motor_current_a = float(current) * self.current_scale
            temperature = self.values.get(lvsg.PARAMETER_TEMPERATURE)
            if temperature is not None:
                reading.motor_temperature_pct = float(temperature & 0xFF)
        reading.details = self._details(status, state_byte)
        if state_byte is not None and bit(state_byte, lvsg.STATE_BIT_COMMS_FAILURE):
            reading.fault = 'communication failure between the Profibus Module and the MCD 200'
        if state_byte is not None and bit(state_byte, lvsg.STATE_BIT_CURRENT_ABOVE_FLC):
            reading.warnings.append('motor current exceeds FLC')
        return reading

    def _state(self, status: lvsg.Status, state_byte: Optional[int]) -> str:
        known = lvsg.MCD200_STATES.get(state_byte & 0x0F) if state_byte is not None else None
        if status.fault:
            return 'tripped'
        if status.on and status.ramping:
            if known in ('starting', 'stopping'):
                return known
            return 'starting' if self.control and self.control.fwd_run else 'stopping'
        if status.on:
            return 'running'
        if status.ready:
            return 'ready'
        return known if known in ('restart_delay', 'unknown') else 'not_ready'

    @staticmethod
    def _status_word(status: lvsg.Status) -> int:
        data = lvsg.encode_status(status.ready, status.on, status.fault, status.ramping,
                                  status.current_raw)
        return data[1] << 8 | data[0]

    def _details(self, status: lvsg.Status, state_byte: Optional[int]) -> Dict[str, str]:
        details = {
            'model': self.model or 'auto (waiting for operating parameters)',
            'module': 'extended' if self.extended else 'basic',
            'ready': str(status.ready), 'on': str(status.on), 'fault': str(status.fault),
            'ramping': str(status.ramping),
            'motor_current_pct_flc': f'{status.current_pct_flc:.0f}',
            'control_fwd_run': str(bool(self.control and self.control.fwd_run)),
            'control_quick_stop': str(bool(self.control and self.control.quick_stop)),
            'commanded_since_connect': str(self.commanded),
        }
        product = self.values.get(lvsg.PARAMETER_PRODUCT)
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
    def command_plan(self, command: str) -> CommandPlan:
        """Return the output-image writes of ``command``; the image is committed on ack."""
        base = self.control or Control()
        if command == 'start':
            steps = [Control(fwd_run=True)]
        elif command == 'stop':
            steps = [Control()]
        elif command == 'quick_stop':  # Quick Stop set before Fwd Run is cleared
            steps = [Control(fwd_run=base.fwd_run, quick_stop=True), Control(quick_stop=True)]
        elif command == 'reset':  # a pulse on bit 3, with Fwd Run clear: never a restart
            steps = [Control(reset=True, quick_stop=base.quick_stop),
                     Control(quick_stop=base.quick_stop)]
        else:
            raise CommandRefused(f'MCD 200 starters have no {command} command (allowed: '
                                 'start, stop, quick_stop, reset)')

        def acknowledged() -> None:
            self.control = steps[-1]
            self.commanded = True

        def failed() -> None:
            # A stop, quick stop or reset was asked for: the image rewritten each cycle keeps
            # Fwd Run clear from now on. A start that failed is not repeated.
            if command != 'start':
                acknowledged()
        return CommandPlan(command, tuple(self.image_write(step) for step in steps),
                           acknowledged, failed)

    def parameter_plan(self, number: int, value=None):
        """Refuse: the Profibus Module gives no parameter access (only parameters 1-4)."""
        raise CommandRefused('the MCD 200 Profibus Module has no parameter access; the '
                             'extended module reads operating parameters 1-4 by itself')

    def explain_exception(self, code: int, detail: Optional[int] = None) -> str:
        """Return technician text for a Modbus exception from the gateway."""
        return f'{GATEWAY_EXCEPTIONS.get(code, "gateway exception")}, Modbus exception ' \
               f'{code:02d}'
