"""The joints as configured and their run-time records, shared by the joints' parts."""

from dataclasses import dataclass
import threading
from typing import Dict, List, Optional, Sequence, Tuple

from drive_bridge.config import model as cfg
from drive_bridge.ros.node.joints.auto_start import AutoStart


@dataclass
class JointSpec:
    """One joint as configured: its drive, name, scale and command mode."""

    device: str
    name: str
    velocity_scale: float  # rad/s of the joint at 100 % reference
    command_mode: str = 'reference'
    auto_stop_delay_s: float = 1.0


def joint_specs(devices: Sequence[cfg.DeviceConfig]) -> List[JointSpec]:
    """Return the joints among ``devices``: the drives with a velocity_scale."""
    return [JointSpec(device.name, cfg.joint_name_of(device), device.option('velocity_scale'),
                      device.option('command_mode', 'reference'),
                      device.option('auto_stop_delay', 1.0))
            for device in devices if device.is_joint]


class Integrator:
    """Position from velocity samples: a trapezoid between two consecutive readings."""

    def __init__(self):
        self.position_rad = 0.0
        self._last: Optional[Tuple[float, float]] = None  # (stamp_s, velocity)

    def add(self, stamp_s: float, velocity: float) -> float:
        """Take a sample; return the position at its time."""
        if self._last is not None and stamp_s > self._last[0]:
            last_stamp_s, last_velocity = self._last
            self.position_rad += 0.5 * (last_velocity + velocity) * (stamp_s - last_stamp_s)
        self._last = (stamp_s, velocity)
        return self.position_rad

    def interrupt(self) -> None:
        """Forget the last sample (an outage): the next one adds no area."""
        self._last = None


class Joint:
    """The run-time record of one joint."""

    def __init__(self, spec: JointSpec):
        self.spec = spec
        self.integrator = Integrator()
        self.auto = AutoStart(spec.auto_stop_delay_s)
        self.velocity = 0.0
        self.published = 0


class JointTable:
    """
    The joints of one node by drive and by name, and the lock over their records.

    The states (bus thread), the commands (commands thread), the settings (executor thread)
    and the automatic starts' outcomes (the bus's future callbacks) change a record only
    while holding ``lock``, and never call the bus while holding it.
    """

    def __init__(self, specs: Sequence[JointSpec]):
        self.by_device: Dict[str, Joint] = {spec.device: Joint(spec) for spec in specs}
        self.by_name: Dict[str, Joint] = {joint.spec.name: joint
                                          for joint in self.by_device.values()}
        self.lock = threading.Lock()
