"""
Soak: 100,000 transactions on one bus with 10 % faults, checked by the oracle.

Outages and trips too; prints the figures. Devices: MCD 500, MCD 3000, FC 51, VLT 5000,
an MCD 202 behind a Profibus gateway, a monitor-only FC 51 and one address nobody answers
(see :mod:`soak_harness.runner`). Run:
.venv/bin/python bench/soak.py [transactions] [fault rate] [seed] [timeout s]
    [--line pty|virtual] [--broken VARIANT|all] [--in-flight N] [--no-lvsg-quick-stop]
``--broken`` runs deliberately broken bridges (:mod:`soak_harness.broken`) and
then the unbroken one with the same settings, and prints what the oracle caught.
"""

import argparse
import sys

from paced_line import TEST_DIR

sys.path.insert(0, TEST_DIR)  # the soak harness (test/soak_harness: test code, not shipped)
from soak_harness.broken import broken, EXPECTED_KINDS, VARIANTS  # noqa: E402
from soak_harness.runner import run_soak, SoakSettings, transport_class  # noqa: E402


def parse(argv) -> argparse.Namespace:
    """Return the arguments."""
    parser = argparse.ArgumentParser(description=__doc__.strip().split('\n')[0])
    parser.add_argument('transactions', nargs='?', type=int, default=100_000)
    parser.add_argument('fault_rate', nargs='?', type=float, default=0.1)
    parser.add_argument('seed', nargs='?', type=int, default=1)
    parser.add_argument('timeout', nargs='?', type=float, default=0.1)
    parser.add_argument('--line', choices=('pty', 'virtual'), default='pty')
    parser.add_argument('--broken', choices=VARIANTS + ('all',))
    parser.add_argument('--in-flight', type=int, default=2,
                        help='commands in flight per device (default 2)')
    parser.add_argument('--no-lvsg-quick-stop', dest='lvsg_quick_stop', action='store_false',
                        help='no quick stops to the gateway')
    return parser.parse_args(argv[1:])


def main(argv) -> int:
    """Run the soak (or the broken variants) and print the report."""
    args = parse(argv)
    settings = SoakSettings(transactions=args.transactions, fault_rate=args.fault_rate,
                            seed=args.seed, timeout_s=args.timeout, line=args.line,
                            in_flight_per_device=args.in_flight,
                            lvsg_quick_stop=args.lvsg_quick_stop)
    print(f'soak on the {settings.line} line: {settings.transactions} transactions, '
          f'{settings.fault_rate:.0%} faults, seed {settings.seed}, timeout '
          f'{settings.timeout_s * 1000:.0f} ms', flush=True)
    if args.broken:
        return catch(settings, VARIANTS if args.broken == 'all' else (args.broken,))
    report = run_soak(settings, progress=lambda done: print(f'  {done} transactions',
                                                            flush=True))
    for line in report.lines():
        print(line)
    return 0 if report.passed else 1


def catch(settings: SoakSettings, variants) -> int:
    """Run each broken variant and the unbroken bridge; return 0 if all are as expected."""
    failures = 0
    for variant in variants:
        with broken(variant, transport_class(settings.line), settings.seed):
            report = run_soak(settings)
        counts = report.violation_counts
        caught = any(counts[kind] for kind in EXPECTED_KINDS[variant])
        failures += not caught
        print(f'{variant}: {"CAUGHT" if caught else "NOT CAUGHT"}: {len(report.violations)} '
              f'violations ({", ".join(f"{k} {n}" for k, n in sorted(counts.items()))}) in '
              f'{report.transactions} transactions', flush=True)
        for violation in report.violations[:2]:
            print(f'    {violation.line()}')
    report = run_soak(settings)
    failures += not report.passed
    print(f'unbroken: {len(report.violations)} violations in {report.transactions} '
          f'transactions: {"PASS" if report.passed else "FAIL"}')
    return 1 if failures else 0


if __name__ == '__main__':
    sys.exit(main(sys.argv))
