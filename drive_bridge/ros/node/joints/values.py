"""What the joints show in ``/diagnostics``: each joint's values and the commands' status."""

from typing import Callable, List

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from drive_bridge.ros.node.joints.commands import CommandCounts
from drive_bridge.ros.node.joints.model import JointTable

RECENT_S = 10.0  # /diagnostics warns while a command was ignored this recently


class JointValues:
    """The joints' /diagnostics values, read from the joint table and the command counts."""

    def __init__(self, table: JointTable, counts: CommandCounts, clock: Callable[[], float]):
        self._table = table
        self._counts = counts
        self._clock = clock

    def device_values(self, device: str) -> List[KeyValue]:
        """Return the joint values of one device for its /diagnostics status."""
        joint = self._table.by_device.get(device)
        if joint is None:
            return []
        spec, auto = joint.spec, joint.auto
        with self._table.lock:
            values = {
                'joint_name': spec.name, 'velocity_scale_rad_s': f'{spec.velocity_scale:g}',
                'joint_velocity_rad_s': f'{joint.velocity:.4f}',
                'joint_position_rad': f'{joint.integrator.position_rad:.4f}',
                'joint_states_published': str(joint.published),
                'command_mode': spec.command_mode}
            if spec.command_mode == 'auto_start' or auto.starts or auto.stops:
                values.update({
                    'auto_stop_delay_s': f'{spec.auto_stop_delay_s:g}',
                    'auto_starts': str(auto.starts), 'auto_stops': str(auto.stops),
                    'auto_start_failures': str(auto.failed_starts),
                    'auto_start': f'waits for a zero command: {auto.blocked}'
                    if auto.blocked else 'armed'})
        return [KeyValue(key=key, value=value) for key, value in values.items()]

    def commands_status(self, name: str) -> DiagnosticStatus:
        """Return the status of ``~/joint_commands`` (``name`` from status_name)."""
        counts = self._counts.copy()
        counters = counts.counters
        by_device, by_name = self._table.by_device, self._table.by_name
        status = DiagnosticStatus(name=name, hardware_id='ros2_control joint commands')
        recent = self._clock() - counts.last_ignored_s < RECENT_S
        status.level = DiagnosticStatus.WARN if recent else DiagnosticStatus.OK
        status.message = counts.last_ignored if recent else \
            f'{len(by_device)} joints: {", ".join(by_name)}'
        values = {'joints': ', '.join(f'{joint.spec.name} ({device})'
                                      for device, joint in by_device.items()),
                  'messages': counters['messages'],
                  'unknown_joint_names': counters['unknown_names'],
                  'messages_without_velocity': counters['without_velocity'],
                  'messages_malformed': counters['malformed'],
                  'last_ignored': counts.last_ignored}
        status.values = [KeyValue(key=key, value=str(value)) for key, value in values.items()]
        return status
