"""
Runtime changes of the joints' ``command_mode`` and ``auto_stop_delay`` (executor thread).

:meth:`JointSettings.check_settings` runs before the bus applies a change (a refusal leaves
everything as it was); :meth:`JointSettings.apply_settings` after. A switch to auto_start
waits for a zero command before the first automatic start, so switching the mode never
starts a motor by itself; a monitor-only drive is never put in auto_start.
"""

from typing import Any, Dict

from drive_bridge.bus.master import BusMaster
from drive_bridge.errors import ConfigError
from drive_bridge.ros.node.joints.auto_start import SWITCHED
from drive_bridge.ros.node.joints.model import JointTable

SettingChanges = Dict[str, Dict[str, Any]]  # device -> setting name -> checked value


class JointSettings:
    """Checks and applies the joints' runtime settings."""

    def __init__(self, bus: BusMaster, table: JointTable, logger):
        self._bus = bus
        self._table = table
        self._logger = logger

    def check_settings(self, changes: SettingChanges) -> None:
        """Raise ConfigError for a runtime change the joints cannot take (nothing applied)."""
        for device, settings in changes.items():
            mode = settings.get('command_mode')
            if mode is None:
                continue
            if device not in self._table.by_device:
                if mode != 'reference':
                    raise ConfigError(f'parameter {device + ".command_mode"!r} = {mode!r} '
                                      f'applies to joints only: {device} has no '
                                      'velocity_scale')
                continue
            allow = settings.get('allow_control', self._bus.snapshot(device).allow_control)
            if mode == 'auto_start' and not allow:
                raise ConfigError(f'parameter {device + ".command_mode"!r} = \'auto_start\' '
                                  'is refused: a monitor-only drive (allow_control false) is '
                                  'never started')

    def apply_settings(self, changes: SettingChanges) -> None:
        """Take runtime changes of command_mode and auto_stop_delay (see the module)."""
        for device, settings in changes.items():
            joint = self._table.by_device.get(device)
            if joint is None or not ({'command_mode', 'auto_stop_delay'} & set(settings)):
                continue
            spec = joint.spec
            holding = self._bus.snapshot(device).holds_run
            before = (spec.command_mode, spec.auto_stop_delay_s)
            with self._table.lock:
                spec.command_mode = settings.get('command_mode', spec.command_mode)
                spec.auto_stop_delay_s = settings.get('auto_stop_delay', spec.auto_stop_delay_s)
                joint.auto.delay_s = spec.auto_stop_delay_s
                if spec.command_mode != before[0]:
                    joint.auto.reset(spec.auto_stop_delay_s, holding, SWITCHED
                                     if spec.command_mode == 'auto_start' else '')
            if (spec.command_mode, spec.auto_stop_delay_s) != before:
                waits = '; automatic starts wait for a zero command first' \
                    if spec.command_mode != before[0] == 'reference' else ''
                self._logger.info(f'{device} (joint {spec.name}): command_mode '
                                  f'{spec.command_mode}, auto_stop_delay '
                                  f'{spec.auto_stop_delay_s:g} s{waits}')
