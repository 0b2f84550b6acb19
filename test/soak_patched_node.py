"""
Run drive_bridge_node with one safety rule broken on purpose (the node soak's catch proof).

Usage: python test/soak_patched_node.py VARIANT --ros-args --params-file FILE; VARIANT is one
of :data:`soak_harness.broken.VARIANTS`. Never run it against real equipment.
"""

import sys

from drive_bridge.ros.node import process
from drive_bridge.transport.serial_rtu import RtuSerialTransport
from soak_harness.broken import broken


def main() -> int:
    """Break the bridge as the first argument says, then run the node with the rest."""
    variant = sys.argv.pop(1)
    with broken(variant, RtuSerialTransport):
        return process.main(sys.argv)


if __name__ == '__main__':
    sys.exit(main())
