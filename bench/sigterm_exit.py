"""
Benchmark: SIGTERM rounds of ``drive_bridge_node`` with a CPU hog beside it (safety case 10).

Each round starts the node on a simulated FC 51 and sends SIGTERM at a random moment: every
third round right after the node's first message (it may still be activating), every
third with a start call in flight, the others once the drive is ready, each after a random
pause of up to 0.5 s. A clean exit is status 0 without a traceback (rclpy's context race,
ros2/rclpy#398, used to give exit 1 with a traceback). Prints the count of clean exits, the
exit times, and the log of every round that was not clean.
Run: .venv/bin/python bench/sigterm_exit.py [rounds (default 50)] [--no-hog]
"""

import os
import random
import statistics
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
TEST_DIR = os.path.join(HERE, '..', 'test')
sys.path[:0] = [HERE, TEST_DIR, os.path.join(TEST_DIR, 'ros')]

from paced_line import ros_environment  # noqa: E402

ros_environment()
os.environ['ROS_PYTHON_CHECK_FIELDS'] = '1'
import rclpy  # noqa: E402 - after the environment it reads
from ros_helpers import write_params  # noqa: E402
from safety_helpers import CpuHog  # noqa: E402
from safety_ros import make_rig, sigterm_round  # noqa: E402

SEED = 10


def main(argv) -> int:
    """Run the rounds and print the figures; exit 1 if any exit was not clean."""
    rounds = int(next((arg for arg in argv if arg.isdigit()), '50'))
    hog = '--no-hog' not in argv
    rclpy.init(domain_id=int(os.environ['ROS_DOMAIN_ID']))
    rig = make_rig('fc')
    failures, times = [], []
    chance = random.Random(SEED)
    try:
        with tempfile.TemporaryDirectory() as folder:
            params = write_params(os.path.join(folder, 'sigterm.yaml'), rig.bus_settings(),
                                  rig.devices)
            hogging = CpuHog() if hog else None
            if hogging:
                hogging.__enter__()
            try:
                for index in range(rounds):
                    started = time.monotonic()
                    failure = sigterm_round(params, rig, chance, index)
                    times.append(time.monotonic() - started)
                    if failure:
                        failures.append(failure)
                    print(f'round {index + 1}/{rounds}: {"FAILED" if failure else "clean"}',
                          flush=True)
            finally:
                if hogging:
                    hogging.__exit__(None, None, None)
    finally:
        rig.stop()
        rclpy.try_shutdown()
    for failure in failures:
        print(f'\n{failure}')
    print(f'\n{rounds - len(failures)} of {rounds} SIGTERMs exited 0 without a traceback '
          f'({"with" if hog else "without"} a CPU hog); a round (start to exit) took '
          f'{statistics.median(times):.2f} s median, {max(times):.2f} s at most')
    return 1 if failures else 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
