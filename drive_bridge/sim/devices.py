"""Every simulated device model by name (from the simulator registry), and a simulated bus."""

import time
from typing import Dict, Optional

from drive_bridge.sim.modbus_server import ModbusSimServer, WireTiming
from drive_bridge.sim.registry import SIM_MODELS, SIMULATORS


def make_device(model: str, now_s: Optional[float] = None, unit: Optional[int] = None,
                line: Optional[Dict[str, object]] = None, **settings):
    """
    Return one simulated device of ``model`` (settings go to its family's config).

    ``unit`` and ``line`` (protocol, baudrate, parity, stopbits): where it is served, for a
    device that reports them (the FC 51's par. 8-30..8-33); the others ignore them.
    """
    if model not in SIM_MODELS:
        raise ValueError(f'unknown simulated model {model!r}: allowed {", ".join(SIM_MODELS)}')
    simulator = SIMULATORS[SIM_MODELS[model]]
    if simulator.knows_its_line and unit is not None:
        settings = dict(settings, address=unit, **(line or {}))
    return simulator.make_device(model, time.monotonic() if now_s is None else now_s,
                                 **settings)


def wire_line(wire: Optional[WireTiming]) -> Dict[str, object]:
    """Return the line settings of a paced wire (none: the devices' defaults, 9600 8E1)."""
    if wire is None:
        return {}
    return {'baudrate': wire.baudrate, 'parity': wire.parity, 'stopbits': wire.stopbits}


def make_sim_server(models: Dict[int, str], wire: Optional[WireTiming] = None,
                    settings: Optional[Dict[str, dict]] = None) -> ModbusSimServer:
    """
    Return a simulated bus with one device per address: ``{20: 'mcd500', 1: 'fc51'}``.

    ``settings`` maps a family (``mcd``, ``fc``, ``vlt``) to keyword settings of its devices'
    simulator config, e.g. ``{'fc': {'ramp_up_s': 0.5}}``.
    """
    settings = settings or {}
    now = time.monotonic()
    devices = {unit: make_device(model, now, unit, wire_line(wire),
                                 **settings.get(SIM_MODELS[model], {}))
               for unit, model in models.items()}
    return ModbusSimServer(devices, wire=wire)
