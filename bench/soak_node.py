"""
Soak through the node, checked by the oracle; prints the figures.

drive_bridge_node on the soak line with 10 % faults, outages and trips, random service calls
(several in flight) and references, then SIGTERM; the oracle checks the line's log against
the client's record.

Run: .venv/bin/python bench/soak_node.py [duration s] [seed] [fault rate] [timeout s]
[broken variant]; a broken variant (:mod:`soak_harness.broken`) runs the node with
that safety rule broken on purpose, and the oracle must report it.
"""

import os
import sys
import tempfile

from paced_line import ros_environment, TEST_DIR

ros_environment()
sys.path.insert(0, TEST_DIR)  # the node soak's driver and the ROS test helpers
import rclpy  # noqa: E402 - after the environment it reads
from soak_node import NodeSoakSettings, run_node_soak  # noqa: E402


def main(argv) -> int:
    """Run the node soak and print its report."""
    settings = NodeSoakSettings()
    if len(argv) > 1:
        settings.duration_s = float(argv[1])
    if len(argv) > 2:
        settings.seed = int(argv[2])
    if len(argv) > 3:
        settings.fault_rate = float(argv[3])
    if len(argv) > 4:
        settings.timeout_s = float(argv[4])
    if len(argv) > 5:
        settings.broken = argv[5]  # a deliberately broken node (soak_broken.VARIANTS)
    print(f'node soak: {settings.duration_s:.0f} s, {settings.fault_rate:.0%} faults, seed '
          f'{settings.seed}, timeout {settings.timeout_s * 1000:.0f} ms'
          + (f', BROKEN: {settings.broken}' if settings.broken else ''), flush=True)
    rclpy.init()
    try:
        with tempfile.TemporaryDirectory(prefix='drive_bridge_soak_') as directory:
            report = run_node_soak(settings, directory)
    finally:
        rclpy.try_shutdown()
    for line in report.lines():
        print(line)
    if not report.passed and not settings.broken:
        print(report.output[-4000:])
    return 0 if report.passed else 1


if __name__ == '__main__':
    os.environ.setdefault('PYTHONUNBUFFERED', '1')
    sys.exit(main(sys.argv))
