"""
A set of one device parameter: checked, written, read back, answered in words.

In order, each refusal one line that ends ``nothing written``: the value's type
(:func:`~drive_bridge.devices.remote_parameters.typed_value`: a whole number is taken for a
double); a read-only parameter (a readout, the drive's serial line) answers ``successful``
when the value is the one it holds (so a ``ros2 param dump`` loads back), else refuses; a
value that could run a motor (:func:`~drive_bridge.devices.remote_parameters.
write_refusal`); the table's check (range, resolution, options; as ``drive-bridge set``); a
node that is not active or is closing its bus; a monitor-only device (``allow_control``
false, as the bus has it now): refused here, before anything is queued. Then the write
goes to the bus as one job of the device's
:class:`~drive_bridge.devices.parameter_service.ParameterService` (the CLI's ``set``: the
table's check and the monitor-only refusal again, before anything is sent; the write, RAM,
or RAM and EEPROM with the node's ``save_to_eeprom``; its read back, with no other
transaction between them), and awaited; the answer is the device's own refusal in words
(FC 51: ``rejected by conv: ... not possible in the present mode``), a value that reads
back different, a read back that failed (``written, but the read back failed``), or
success. After a write, or a refusal, the value the device holds goes out on
``/parameter_events`` so that an editor (rqt_reconfigure) shows it.
"""

from typing import Any, Callable, Optional

from drive_bridge.devices import parameter_info as info
from drive_bridge.devices.parameters import check_value
from drive_bridge.devices.remote_parameters import RemoteParameter, typed_value, write_refusal
from drive_bridge.errors import DriveBridgeError, ReadBackMismatch
from drive_bridge.ros.node.device_parameters.device import DeviceParameters
from drive_bridge.ros.node.gate import CommandGate
from drive_bridge.ros.node.service_calls import ServiceCalls
from rcl_interfaces.msg import SetParametersResult

NOTHING = 'nothing written'
HELD_WAIT_S = 0.5  # after a refusal, the value held is read for this long at most


class DeviceWriter:
    """Sets one device's parameters (executor thread, coroutines awaiting the bus)."""

    def __init__(self, device: DeviceParameters, calls: ServiceCalls, gate: CommandGate,
                 give_up_s: float, eeprom: Callable[[], bool],
                 announce: Callable[[RemoteParameter, Any], None]):
        self._device = device
        self._calls = calls
        self._gate = gate
        self._give_up_s = give_up_s
        self._eeprom = eeprom
        self._announce = announce

    async def current(self, parameter: RemoteParameter, wait_s: float) -> Optional[Any]:
        """Return the value held, else read it (within ``wait_s``); None if it cannot be."""
        if not self._device.online():
            return None
        value = self._device.value(parameter)
        if value is not None:
            return value
        try:
            await self._calls.answer_of(self._device.read(parameter), f'read {parameter.name}',
                                        wait_s)
        except DriveBridgeError:
            return None
        return self._device.value(parameter)

    async def set_value(self, parameter: RemoteParameter, given: Any) -> SetParametersResult:
        """Set ``parameter`` to ``given`` (a Python value); return the result in words."""
        if given is None:  # PARAMETER_NOT_SET: what a dump holds for a value not readable
            return SetParametersResult(successful=True, reason=f'no value given: {NOTHING}')
        reason = await self.refusal(parameter, given)
        if reason is None:  # a read-only parameter given the value it holds
            return SetParametersResult(successful=True, reason='unchanged (read-only)')
        if not reason:
            reason = await self._write(parameter, typed_value(parameter, given)[0])
        if reason:
            await self._announce_held(parameter)
        return SetParametersResult(successful=not reason, reason=reason)

    async def refusal(self, parameter: RemoteParameter, given: Any) -> Optional[str]:
        """Return why the value is refused, '' if it may be written, None: unchanged."""
        name = parameter.name
        value, reason = typed_value(parameter, given)
        if reason:
            return f'{reason}; {NOTHING}'
        if parameter.read_only:
            held = await self.current(parameter, self._give_up_s)
            if held is not None and info.same_value(value, held):
                return None
            return f'{name} is read-only ({parameter.read_only}); {NOTHING}'
        reason = write_refusal(self._device.family, parameter.spec, value) or \
            check_value(parameter.spec, value, self._device.factors)
        if reason:
            return f'{name}: {reason}; {NOTHING}'
        if self._gate.bus is None or not self._gate.is_active():
            return f'{name}: {self._gate.inactive_reason().replace("nothing sent", NOTHING)}'
        if not self._device.writes_allowed():
            return f'{self._device.name} is monitor only (allow_control is false): {name} ' \
                f'not set; {NOTHING}'
        return ''

    async def _write(self, parameter: RemoteParameter, value: Any) -> str:
        """Write and read back (one job of the bus); return '' or why it is not written."""
        name = parameter.name
        try:
            written = self._device.write(parameter, value, self._eeprom())
            read = await self._calls.answer_of(written, f'write {name}', self._give_up_s)
        except ReadBackMismatch as error:
            held = self._device.shown(parameter, error.read)
            return f'{name}: wrote {value!r}, but it reads back {held!r}'
        except DriveBridgeError as error:
            return f'{name}: {error}'
        self._announce(parameter, self._device.shown(parameter, read))
        return ''

    async def _announce_held(self, parameter: RemoteParameter) -> None:
        """Announce the value the device holds (an editor's widget snaps back to it)."""
        held = await self.current(parameter, HELD_WAIT_S)
        if held is not None:
            self._announce(parameter, held)
