"""
Every device family, collected from the family modules: the one registry entry of a family.

Configuration, node, CLI and simulators take the families, their models, address ranges,
protocols, settings, profile and simulator factories from here. A new family is its own
module exporting an ``ENTRY`` (:class:`~drive_bridge.devices.contracts.Family`) and one line
below.
"""

from typing import Dict

from drive_bridge.devices import fc51, lvsg, mcd, vlt
from drive_bridge.devices.contracts import Family

FAMILIES: Dict[str, Family] = {entry.name: entry for entry in (
    mcd.ENTRY,
    fc51.ENTRY,
    vlt.ENTRY,
    lvsg.ENTRY,
)}
