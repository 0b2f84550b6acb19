"""
One device's parameters on the bus: the table as ROS sees it, the values read, bus access.

:class:`DeviceParameters` knows the device's remote parameters (by ROS name), holds their
values as last read (:class:`~drive_bridge.ros.node.device_parameters.cache.ValueCache`) and
queues reads and writes on the bus as functions of the device's
:class:`~drive_bridge.devices.parameter_service.ParameterService` (the CLI's: the table's
check, the monitor-only refusal, the write and its read back), which the bus thread runs
between its transactions (``BusMaster.run_parameter_service``; nothing here waits for the
bus). A value read (also a write's read back) is stored, and a change announced
(``on_change``), on the bus thread.

The table is the CLI's (:func:`~drive_bridge.devices.parameter_info.parameter_table`) for
the configured model; with model ``auto`` and a family whose table depends on the model
(MCD), it is taken once the bus has read the model (until then the device lists none).
"""

from concurrent.futures import Future
from dataclasses import replace
from typing import Any, Callable, Dict, List, Optional

from drive_bridge.bus.master import BusMaster
from drive_bridge.config import model as cfg
from drive_bridge.devices import parameter_info as info
from drive_bridge.devices.contracts import ParameterAccess, ParameterOptions
from drive_bridge.devices.fc_profile_drive import FcProfileDrive
from drive_bridge.devices.remote_parameters import remote_parameters, RemoteParameter
from drive_bridge.errors import ReadBackMismatch
from drive_bridge.ros.node.device_parameters.cache import ValueCache


def has_parameters(device: cfg.DeviceConfig) -> bool:
    """Return whether the device's profile reads and writes parameters by number."""
    return isinstance(device.make_spec().profile, ParameterAccess)


class DeviceParameters:
    """The remote parameters of one device, their values as read, and the bus to reach them."""

    def __init__(self, device: cfg.DeviceConfig, bus: BusMaster,
                 on_change: Callable[[RemoteParameter, Any], None]):
        self.device = device
        self.name = device.name
        self.bus = bus
        self.cache = ValueCache()
        self._on_change = on_change
        self._by_name: Dict[str, RemoteParameter] = {}
        self._resolved = False
        profile = device.make_spec().profile
        self.eeprom = isinstance(profile, FcProfileDrive)  # drives store RAM or EEPROM
        self.factors = info.conversion_factors(profile)
        self._resolve()

    def _resolve(self) -> None:
        """Take the table once the model is known (at once unless MCD with model auto)."""
        if self._resolved:
            return
        model = self.device.model
        if model == 'auto' and not isinstance(self.device.make_spec().profile, FcProfileDrive):
            model = self.bus.snapshot(self.name).model
            if model == 'auto':
                return
        profile = replace(self.device, model=model).make_spec().profile
        table = info.parameter_table(profile)
        self._by_name = {parameter.name: parameter
                         for parameter in remote_parameters(table, self.factors)}
        self._resolved = True

    @property
    def parameters(self) -> List[RemoteParameter]:
        """Return the device's remote parameters, in the table's order."""
        self._resolve()
        return list(self._by_name.values())

    def find(self, name: str) -> Optional[RemoteParameter]:
        """Return the parameter called ``name`` (None: no device parameter of that name)."""
        self._resolve()
        return self._by_name.get(name)

    @property
    def family(self) -> str:
        """Return the device's family."""
        return self.device.family

    def online(self) -> bool:
        """Return whether the bus has the device online; forget every value when not."""
        online = self.bus.snapshot(self.name).online is True
        if not online:
            self.cache.forget()
        return online

    def writes_allowed(self) -> bool:
        """Return whether the device takes writes (``allow_control``, as the bus has it now)."""
        return self.bus.snapshot(self.name).allow_control

    def value(self, parameter: RemoteParameter) -> Optional[Any]:
        """Return the value last read of ``parameter`` (None: not held)."""
        return self.cache.value(parameter.number)

    def read(self, parameter: RemoteParameter) -> Future:
        """Queue a read; its value is stored (and a change announced) when it comes."""
        number = parameter.number
        future = self.bus.run_parameter_service(
            self.name, lambda service: service.read(number), label=f'read {parameter.name}')
        future.add_done_callback(lambda done: self._store(parameter, done))
        return future

    def write(self, parameter: RemoteParameter, value: Any, eeprom: bool) -> Future:
        """
        Queue a write of ``value`` (display units), to RAM or (drives) RAM and EEPROM.

        The device's ParameterService on the bus checks it against the table, refuses it on
        a monitor-only device (nothing sent), writes it and reads it back; the future gives
        the value read back, or raises (ReadBackMismatch: the device holds another value,
        which is stored as read).
        """
        number = parameter.number
        options = ParameterOptions(eeprom=eeprom and self.eeprom)
        future = self.bus.run_parameter_service(
            self.name, lambda service: service.write(number, value, options),
            label=f'write {parameter.name}')
        future.add_done_callback(lambda done: self._store_written(parameter, done))
        return future

    def _store_written(self, parameter: RemoteParameter, done: Future) -> None:
        """Keep the value a write read back, also one that differs (bus thread)."""
        if done.cancelled():
            return
        error = done.exception()
        if error is None:
            self._keep(parameter, done.result())
        elif isinstance(error, ReadBackMismatch) and error.read is not None:
            self._keep(parameter, error.read)

    def _store(self, parameter: RemoteParameter, done: Future) -> None:
        """Keep a value read (bus thread); announce it if it changed."""
        if done.cancelled():
            return
        error = done.exception()
        if error is not None:
            if str(error).startswith('rejected by'):  # the device's own refusal
                self.cache.refused(parameter.number, str(error))
            return
        self._keep(parameter, done.result())

    def _keep(self, parameter: RemoteParameter, read: Any) -> None:
        """Store a value read (bus thread); announce it if it changed."""
        value = self.shown(parameter, read)
        before = self.cache.store(parameter.number, value)
        if before is not None and not info.same_value(before, value):
            self._on_change(parameter, value)

    def shown(self, parameter: RemoteParameter, read: Any) -> Any:
        """Return a value as read, as the node shows it (the spec's resolution, no padding)."""
        value = info.display_value(parameter.spec, read, self.factors)
        if isinstance(value, str):
            value = value.rstrip(' ')
        return value
