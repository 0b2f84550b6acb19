"""Every simulated device model by name (from the family registry), and a simulated bus."""

import time
from typing import Dict, Optional

from drive_bridge.devices.registry import FAMILIES
from drive_bridge.sim.modbus_server import ModbusSimServer, WireTiming

# model name -> family name, for every family that has a simulator.
SIM_MODELS: Dict[str, str] = {model: family.name for family in FAMILIES.values()
                              if family.make_simulator is not None
                              for model in family.sim_models}


def make_device(model: str, now_s: Optional[float] = None, **settings):
    """Return one simulated device of ``model`` (settings go to its family's config)."""
    if model not in SIM_MODELS:
        raise ValueError(f'unknown simulated model {model!r}: allowed {", ".join(SIM_MODELS)}')
    family = FAMILIES[SIM_MODELS[model]]
    return family.make_simulator(model, time.monotonic() if now_s is None else now_s,
                                 **settings)


def make_sim_server(models: Dict[int, str], wire: Optional[WireTiming] = None,
                    settings: Optional[Dict[str, dict]] = None) -> ModbusSimServer:
    """
    Return a simulated bus with one device per address: ``{20: 'mcd500', 1: 'fc51'}``.

    ``settings`` maps a family (``mcd``, ``fc``, ``vlt``) to keyword settings of its devices'
    simulator config, e.g. ``{'fc': {'ramp_up_s': 0.5}}``.
    """
    settings = settings or {}
    now = time.monotonic()
    devices = {unit: make_device(model, now, **settings.get(SIM_MODELS[model], {}))
               for unit, model in models.items()}
    return ModbusSimServer(devices, wire=wire)
