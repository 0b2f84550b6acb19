"""
Benchmark: what a dead device and a failed transaction cost the line, with the line discipline.

Three simulated MCD 500 polled as fast as the bus allows on a 19200 baud line paced by the
wire pacer (8E1 timing), with and without a fourth configured address that never answers.
Prints the live devices' polls a second in both cases and their ratio (the issue 40 goal: the
live devices keep 95 % of their rate), and from the pacer's frame log how long each request
to the dead address held the line: from its start to the start of the next request, against
``timeout`` + ``late_reply_guard`` (the bound the quarantine keeps), and the share of the
window those holds took. Each case is measured after a warm-up (by default 30 s: the dead
address's backoff has reached ``backoff_max`` by then), the two cases in turns ``--rounds``
times, since the pacer's own pace varies from run to run on a busy machine. The machine and
its load are printed first and last.
Run: .venv/bin/python bench/dead_device.py [seconds per case, default 60] [timeout s, 0.3]
[warm-up s, 30] [rounds, 2]
"""

import statistics
import sys
import time
from typing import Dict, List

from drive_bridge.bus.events import ReadingEvent
from drive_bridge.bus.master import BusMaster, BusTiming, DeviceSpec
from drive_bridge.devices.mcd import McdProfile
from drive_bridge.sim.wire_pacer import LineTiming, MASTER
from drive_bridge.transport.engines import make_transport
from drive_bridge.transport.link import LinkSettings
from paced_line import PacedSimulator
from thread_cpu import machine

LIVE = (20, 21, 22)
DEAD = 30
BAUDRATE = 19200


def run(seconds: float, timeout_s: float, with_dead: bool, warm_up_s: float) -> Dict[str, object]:
    """Poll the live devices (and the dead one); return their rate and the dead holds."""
    line = PacedSimulator([f'mcd500:{unit}' for unit in LIVE], LineTiming(BAUDRATE, 'E', 1))
    units = LIVE + ((DEAD,) if with_dead else ())
    specs = [DeviceSpec(f'd{unit}', unit, McdProfile('mcd500'), poll_rate_hz=100.0)
             for unit in units]
    link = LinkSettings(port=line.path, baudrate=BAUDRATE, parity='N', timeout_s=timeout_s)
    readings: List[str] = []
    bus = BusMaster(make_transport(link), specs,
                    BusTiming(frame_gap_s=line.timing.gap_s, transaction_timeout_s=timeout_s),
                    listener=lambda event: readings.append(event.device)
                    if isinstance(event, ReadingEvent) else None)
    bus.run_once()
    warm_until = time.monotonic() + warm_up_s
    while time.monotonic() < warm_until:
        bus.run_step()
    live_before = sum(name != f'd{DEAD}' for name in readings)
    started = collected = time.monotonic()
    logged: Dict[float, object] = {}  # the pacer keeps its newest frames only: collect them
    while time.monotonic() - started < seconds:
        bus.run_step()
        if time.monotonic() - collected > 1.0:
            collected = time.monotonic()
            logged.update((frame.start_s, frame) for frame in line.pacer.frames())
    ended = time.monotonic()
    live = sum(name != f'd{DEAD}' for name in readings) - live_before
    bus.shutdown(stop_motors=False)
    logged.update((frame.start_s, frame) for frame in line.pacer.frames())
    requests = [frame for _, frame in sorted(logged.items())
                if frame.sender == MASTER and started <= frame.start_s <= ended]
    line.close()
    holds = [after.start_s - frame.start_s for frame, after in zip(requests, requests[1:])
             if frame.data[0] == DEAD]
    return {'rate': live / (ended - started), 'holds': holds, 'guard': link.guard_s,
            'share': sum(holds) / (ended - started)}


def main() -> None:
    seconds = float(sys.argv[1]) if len(sys.argv) > 1 else 60.0
    timeout_s = float(sys.argv[2]) if len(sys.argv) > 2 else 0.3
    warm_up_s = float(sys.argv[3]) if len(sys.argv) > 3 else 30.0
    rounds = int(sys.argv[4]) if len(sys.argv) > 4 else 2
    print(machine())
    print(f'3 MCD 500 at 100 Hz on {BAUDRATE} baud (8E1 timing, wire pacer), timeout '
          f'{timeout_s:g} s, backoff_max 10 s, {warm_up_s:g} s warm-up, {seconds:g} s a case')
    ratios = []
    for round_number in range(1, rounds + 1):
        alone = run(seconds, timeout_s, False, warm_up_s)
        dead = run(seconds, timeout_s, True, warm_up_s)
        holds = dead['holds']
        ratios.append(dead['rate'] / alone['rate'])
        print(f'round {round_number}: live devices, polls/s: alone {alone["rate"]:.1f}, beside '
              f'a dead address {dead["rate"]:.1f}: {ratios[-1]:.1%} of their rate')
        if holds:
            print(f'  each probe of the dead address held the line (its request start to the '
                  f'next request start): {len(holds)} probes, median '
                  f'{statistics.median(holds) * 1000:.1f} ms, max {max(holds) * 1000:.1f} ms '
                  f'(timeout + guard {(timeout_s + dead["guard"]) * 1000:.0f} ms): '
                  f'{dead["share"]:.1%} of the window')
    print(f'ratio: median {statistics.median(ratios):.1%} of {rounds} rounds')
    print(machine())


if __name__ == '__main__':
    main()
