"""
Reconnect drills: unplugged adapter, drive power cycle, gateway restart; prints the figures.

See :mod:`reconnect_drill`. Run: .venv/bin/python bench/reconnect.py [cycles]
"""

import sys

from paced_line import TEST_DIR

sys.path.insert(0, TEST_DIR)  # the drills (test/reconnect_drill.py: test code, not shipped)
from reconnect_drill import DRILLS, run_drill  # noqa: E402


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
