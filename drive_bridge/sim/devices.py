"""Every simulated device model by name, and one call to build a simulated bus of them."""

import time
from typing import Callable, Dict, Optional

from drive_bridge.devices import mcd
from drive_bridge.sim.fc_device import FcSimDevice
from drive_bridge.sim.fc_model import FcModel, FcSimConfig
from drive_bridge.sim.mcd_device import McdSimDevice
from drive_bridge.sim.mcd_model import McdModel, McdSimConfig
from drive_bridge.sim.modbus_server import ModbusSimServer, WireTiming


def _mcd(model: str, now_s: float, settings: dict) -> McdSimDevice:
    return McdSimDevice(McdModel(McdSimConfig(model=model, **settings), now_s))


def _fc(model: str, now_s: float, settings: dict) -> FcSimDevice:
    return FcSimDevice(FcModel(FcSimConfig(model=model, **settings), now_s))


# model name -> (family, builder taking (model, now_s, settings of that family's config)).
SIM_MODELS: Dict[str, tuple] = {
    **{model: ('mcd', _mcd) for model in mcd.MODEL_FEATURES},
    'fc51': ('fc', _fc),
    'vlt5000': ('vlt', _fc),
    'vlt6000': ('vlt', _fc),
}


def make_device(model: str, now_s: Optional[float] = None, **settings):
    """Return one simulated device of ``model`` (settings go to its family's config)."""
    if model not in SIM_MODELS:
        raise ValueError(f'unknown simulated model {model!r}: allowed {", ".join(SIM_MODELS)}')
    builder: Callable = SIM_MODELS[model][1]
    return builder(model, time.monotonic() if now_s is None else now_s, settings)


def make_sim_server(models: Dict[int, str], wire: Optional[WireTiming] = None,
                    settings: Optional[Dict[str, dict]] = None) -> ModbusSimServer:
    """
    Return a simulated bus with one device per address: ``{20: 'mcd500', 1: 'fc51'}``.

    ``settings`` maps a family (``mcd``, ``fc``, ``vlt``) to keyword settings of its devices'
    simulator config, e.g. ``{'fc': {'ramp_up_s': 0.5}}``.
    """
    settings = settings or {}
    now = time.monotonic()
    devices = {unit: make_device(model, now, **settings.get(SIM_MODELS[model][0], {}))
               for unit, model in models.items()}
    return ModbusSimServer(devices, wire=wire)
