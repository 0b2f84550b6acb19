"""
Every family's simulator: the one sim-side registry entry of a device family.

The device families (:mod:`drive_bridge.devices.registry`) know nothing of their simulators:
the simulators import the families' maps, never the reverse (the import contract in
``.importlinter`` checks it). A family's simulator is a model (behaviour, explicit time) with
its Modbus face and an entry here: the family's name, the models it simulates and the factory
``make_device(model, now_s, **settings)`` (settings go to the model's config).
"""

from dataclasses import dataclass
from typing import Callable, Dict, Tuple

from drive_bridge.devices import fc51, mcd, vlt
from drive_bridge.sim.fc_profile_modbus_device import make_drive_device
from drive_bridge.sim.mcd_device import make_mcd_device
from drive_bridge.sim.modbus_server import SimDevice


@dataclass(frozen=True)
class Simulator:
    """One device family's simulator: its models and the factory of one simulated device."""

    family: str  # the name in drive_bridge.devices.registry.FAMILIES
    models: Tuple[str, ...]
    make_device: Callable[..., SimDevice]  # (model, now_s, **settings) -> a Modbus face
    # Its config takes the line it is served on (address, protocol, baudrate, parity,
    # stopbits): the FC 51 reports them as its par. 8-30..8-33.
    knows_its_line: bool = False


SIMULATORS: Dict[str, Simulator] = {entry.family: entry for entry in (
    Simulator(mcd.FAMILY, tuple(mcd.MODEL_FEATURES), make_mcd_device),
    Simulator(fc51.FAMILY, ('fc51',), make_drive_device, knows_its_line=True),
    Simulator(vlt.FAMILY, vlt.MODELS, make_drive_device, knows_its_line=True),
)}

# model name -> family name, for every simulated model.
SIM_MODELS: Dict[str, str] = {model: entry.family for entry in SIMULATORS.values()
                              for model in entry.models}
