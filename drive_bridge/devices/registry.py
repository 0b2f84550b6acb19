"""Which device families exist, their models, address ranges and profile factories."""

from dataclasses import dataclass
from typing import Callable, Dict, Tuple

from drive_bridge.devices import mcd


@dataclass(frozen=True)
class Family:
    """One device family as the configuration sees it."""

    name: str
    description: str
    models: Tuple[str, ...]
    address_range: Tuple[int, int]
    protocols: Tuple[str, ...]
    is_drive: bool
    make_profile: Callable[..., object]


FAMILIES: Dict[str, Family] = {
    'mcd': Family(
        name='mcd',
        description='MCD 201/202/500 via the MCD Modbus Module, MCD 3000 via the Remote Operator',
        models=mcd.MODELS, address_range=mcd.ADDRESS_RANGE,
        protocols=('modbus_rtu', 'modbus_tcp', 'rtu_over_tcp'), is_drive=False,
        make_profile=lambda model, current_scale: mcd.McdProfile(model, current_scale)),
}
# Families of the ROS contract that this version does not implement yet.
PLANNED_FAMILIES = ('vlt', 'fc', 'lvsg')
