"""Every simulated device model by name (from the simulator registry), and a simulated bus."""

import time
from typing import Dict, Optional

from drive_bridge.sim.modbus_server import ModbusSimServer, WireTiming
from drive_bridge.sim.registry import SIM_MODELS, SIMULATORS


def make_device(model: str, now_s: Optional[float] = None, **settings):
    """Return one simulated device of ``model`` (settings go to its family's config)."""
    if model not in SIM_MODELS:
        raise ValueError(f'unknown simulated model {model!r}: allowed {", ".join(SIM_MODELS)}')
    simulator = SIMULATORS[SIM_MODELS[model]]
    return simulator.make_device(model, time.monotonic() if now_s is None else now_s,
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
