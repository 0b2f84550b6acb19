"""
Run drive_bridge_node with one safety rule broken on purpose (the node soak's catch proof).

Usage: python test/soak_patched_node.py VARIANT --ros-args --params-file FILE; VARIANT is one
of :data:`drive_bridge.tools.soak_broken.VARIANTS`. Never run it against real equipment.
"""

import sys

from drive_bridge.ros import process
from drive_bridge.tools.soak_broken import broken
from drive_bridge.transport.serial_rtu import RtuSerialTransport


def main() -> int:
    """Break the bridge as the first argument says, then run the node with the rest."""
    variant = sys.argv.pop(1)
    with broken(variant, RtuSerialTransport):
        return process.main(sys.argv)


if __name__ == '__main__':
    sys.exit(main())
