"""Which device families exist, their models, address ranges and profile factories."""

from dataclasses import dataclass
from typing import Callable, Dict, Tuple

from drive_bridge.devices import fc, lvsg, mcd, vlt
from drive_bridge.devices.drive import DriveProfile
from drive_bridge.devices.mcd_ascii import McdAsciiProfile


@dataclass(frozen=True)
class Family:
    """One device family as the configuration sees it."""

    name: str
    description: str
    models: Tuple[str, ...]
    address_range: Tuple[int, int]
    protocols: Tuple[str, ...]
    is_drive: bool
    make_profile: Callable[..., object]  # takes a validated device config


def _drive_profile(data):
    def make(device) -> DriveProfile:
        overrides = {'motor_current': device.current_parameter} \
            if device.current_parameter else {}
        return DriveProfile(data, device.model, device.current_scale, device.comms_timeout,
                            device.comms_timeout_function, overrides,
                            device.drive_link_timeout)
    return make


FAMILIES: Dict[str, Family] = {
    'mcd': Family(
        name='mcd',
        description='MCD 201/202/500 via the MCD Modbus Module, MCD 3000 via the Remote Operator',
        models=mcd.MODELS, address_range=mcd.ADDRESS_RANGE,
        protocols=('modbus_rtu', 'modbus_tcp', 'rtu_over_tcp', 'ap_ascii'), is_drive=False,
        make_profile=lambda device: (McdAsciiProfile if device.protocol == 'ap_ascii'
                                     else mcd.McdProfile)(device.model, device.current_scale)),
    'fc': Family(
        name='fc', description='VLT Micro Drive FC 51, built-in Modbus RTU',
        models=fc.MODELS, address_range=fc.ADDRESS_RANGE,
        protocols=('modbus_rtu', 'modbus_tcp', 'rtu_over_tcp'), is_drive=True,
        make_profile=_drive_profile(fc.DATA)),
    'vlt': Family(
        name='vlt', description='VLT 5000 / VLT 6000 HVAC with the Modbus RTU option card',
        models=vlt.MODELS, address_range=vlt.ADDRESS_RANGE,
        protocols=('modbus_rtu', 'modbus_tcp', 'rtu_over_tcp'), is_drive=True,
        make_profile=_drive_profile(vlt.DATA)),
    'lvsg': Family(
        name='lvsg', description='MCD 200 with the Profibus Module, through a DP-master '
        'gateway that maps the LVSG process image to Modbus registers',
        models=lvsg.MODELS, address_range=lvsg.ADDRESS_RANGE,
        protocols=('modbus_tcp', 'rtu_over_tcp', 'modbus_rtu'), is_drive=False,
        make_profile=lambda device: lvsg.LvsgProfile(
            device.model, device.current_scale, device.gateway_input_register,
            device.gateway_output_register, device.gateway_byte_order, device.lvsg_module)),
}
