"""
Benchmark: what one wake-up of a waiting thread costs in CPU on this machine.

The bus thread waits several times a transaction (for the end of the inter-frame gap, for
the reply's bytes); each wait it wakes from costs the thread CPU beyond the work it then
does. This bench times a bare loop of waits with nothing else to do, in the thread's own CPU
clock (``time.thread_time``): ``threading.Event.wait`` (how the bus thread waits for the
gap, so a command can wake it), ``time.sleep`` (the rest of the gap), and the two one after
the other (the bus thread's pair). The waits are 1.5 ms and 0.3 ms, as at 19200 baud. Each
case runs ``rounds`` times in turn; the median and range are printed, in µs a wait (for
the pair, a pair).
Run: .venv/bin/python bench/wake_cost.py [waits per round, default 1500] [rounds, default 3]
"""

import statistics
import sys
import threading
import time
from typing import Callable, Dict, List

import thread_cpu

GAP_WAIT_S = 0.0015
REST_S = 0.0003


def cost_us(wait: Callable[[], None], count: int) -> float:
    """Return the thread's CPU in µs for one ``wait()``, over ``count`` of them."""
    started = time.thread_time()
    for _ in range(count):
        wait()
    return 1e6 * (time.thread_time() - started) / count


def main() -> None:
    count = int(sys.argv[1]) if len(sys.argv) > 1 else 1500
    rounds = int(sys.argv[2]) if len(sys.argv) > 2 else 3
    print(thread_cpu.machine())
    event = threading.Event()
    cases: Dict[str, Callable[[], None]] = {
        'Event.wait(1.5 ms)': lambda: event.wait(GAP_WAIT_S),
        'time.sleep(1.5 ms)': lambda: time.sleep(GAP_WAIT_S),
        'Event.wait(1.5 ms), then time.sleep(0.3 ms)':
            lambda: (event.wait(GAP_WAIT_S), time.sleep(REST_S)),
    }
    results: Dict[str, List[float]] = {name: [] for name in cases}
    for _ in range(rounds):
        for name, wait in cases.items():
            results[name].append(cost_us(wait, count))
    for name, values in results.items():
        values.sort()
        print(f'{name}: {statistics.median(values):.1f} µs of CPU a time '
              f'[{values[0]:.1f}, {values[-1]:.1f}], {count} times a round, {rounds} rounds')
    print(thread_cpu.load())


if __name__ == '__main__':
    main()
