"""
Reconnect drills: unplugged adapter, drive power cycle, gateway restart; prints the figures.

See :mod:`drive_bridge.tools.reconnect`. Run: .venv/bin/python bench/reconnect.py [cycles]
"""

import sys

from drive_bridge.tools.reconnect import DRILLS, run_drill


def main(argv) -> int:
    """Run every drill and print how fast the loss was reported and the link recovered."""
    cycles = int(argv[1]) if len(argv) > 1 else 20
    failed = False
    for drill in DRILLS:
        report = run_drill(drill, cycles)
        print(report.line(), flush=True)
        failed = failed or bool(report.failures)
    return 1 if failed else 0


if __name__ == '__main__':
    sys.exit(main(sys.argv))
