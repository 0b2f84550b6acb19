"""
Soak: 100,000 transactions on one mixed bus with 10 % injected faults; prints the figures.

Devices: MCD 500, MCD 3000, FC 51, VLT 5000, an MCD 202 behind a Profibus gateway, and one
address nobody answers (see :mod:`drive_bridge.tools.soak`). Run:
.venv/bin/python bench/soak.py [transactions] [fault rate] [seed] [timeout s]
"""

import sys

from drive_bridge.tools.soak import run_soak, SoakSettings


def main(argv) -> int:
    """Run the soak with the arguments given and print its report."""
    settings = SoakSettings()
    if len(argv) > 1:
        settings.transactions = int(argv[1])
    if len(argv) > 2:
        settings.fault_rate = float(argv[2])
    if len(argv) > 3:
        settings.seed = int(argv[3])
    if len(argv) > 4:
        settings.timeout_s = float(argv[4])
    print(f'soak: {settings.transactions} transactions, {settings.fault_rate:.0%} faults, '
          f'seed {settings.seed}, timeout {settings.timeout_s * 1000:.0f} ms', flush=True)
    report = run_soak(settings, progress=lambda done: print(f'  {done} transactions',
                                                            flush=True))
    for line in report.lines():
        print(line)
    return 0 if report.passed else 1


if __name__ == '__main__':
    sys.exit(main(sys.argv))
