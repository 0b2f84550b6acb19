"""
Benchmark: from a ``~/joint_commands`` message to the frame that carries its reference.

FC 51 joints on one line paced by the wire pacer (8E1 timing), started and polled as fast
as the line allows (``poll_rate`` 100), through ``drive_bridge_node``. A controller in this
process publishes every joint's velocity at 100 Hz (reliable, as JointStateTopicSystem
does) and, at random moments (once the last step's frames are seen, after a random pause of
up to 0.2 s, so that the steps land at every phase of the poll cycle), steps every joint to
a new velocity that no earlier step used. The pacer and the controller share this
process's monotonic clock: the latency of a joint is from the first message carrying its
new velocity to the start of the first frame on the wire that carries the new reference
word to its drive (Modbus RTU: the control write of coils 1-32 with the run word and that
reference, matched byte for byte; FC protocol: a telegram to its address with the run word
in PCD1 and that reference in PCD2).

The bound is one poll cycle plus one transaction: the node writes the latest reference
with the drive's next poll, so a message that just misses a control write waits for the
next one (one cycle of the line, from that drive's control write to its next, by the frame
log; a cycle with a slow readout in it is longer, so the bound takes the 99th percentile of
the cycles, as the latency's) and for that write's transaction (request, reply and both
silences, median). Prints p50, p99 and the largest latency per configuration, the bound,
whether p99 is within it and within the stricter median cycle + one transaction, and how
many messages a control write skipped: one that started more than 5 ms after the message
without carrying it (the reference must go with the drive's next poll: 0).
Run: .venv/bin/python bench/joint_latency.py [steps] [--configs modbus_rtu:38400:2 ...]
"""

import argparse
import os
import random
import statistics
import threading
import time
from typing import Dict, List, Optional, Tuple

from drive_bridge.devices import fc51
from drive_bridge.devices.fc_profile_drive import FcProfileModbusDrive
from drive_bridge.protocol import fc_profile, fc_telegram
from drive_bridge.protocol.commands import Command
from drive_bridge.sim.wire_pacer import LineTiming, MASTER, WireFrame
from joint_cpu import devices, SCALE, start_drives
from joint_rates import GAPS, SIMULATOR_PROTOCOLS
from node_cpu import wait_until_ready
from paced_line import conditions, node_bus, NodeProcess, PacedSimulator, ros_environment
import thread_cpu

ros_environment()
import rclpy  # noqa: E402, I100 - after the environment it reads
from rclpy.qos import QoSProfile, ReliabilityPolicy  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

COMMAND_PERIOD_S = 0.01
PAUSE_S = (0.0, 0.2)  # after the step's frames: lands the next step at any phase
FRAME_TIMEOUT_S = 3.0
# A control write that starts this long after a message and does not carry it skipped it:
# the step is chosen 0.5 ms before its frame, and the message takes a moment to reach the bus.
MISS_ALLOWANCE_S = 0.005
SEED = 29
RUN_WORD = fc_profile.COMMAND_WORDS[Command.START]
PROFILE = FcProfileModbusDrive(fc51.DATA, 'fc51')
DEFAULT_CONFIGS = ('modbus_rtu:38400:2', 'modbus_rtu:115200:8', 'fc_protocol:38400:2',
                   'fc_protocol:115200:8')


class Controller:
    """Publish every joint's velocity at 100 Hz from a thread; note when a step first goes."""

    def __init__(self, names: List[str]):
        self.node = rclpy.create_node(f'bench_latency_{os.getpid()}')
        self.publisher = self.node.create_publisher(
            JointState, '/drive_bridge/joint_commands',
            QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE))
        self.names = names
        self.velocities = [5.0] * len(names)
        self._pending: Optional[Tuple[List[float], threading.Event]] = None
        self.step_s = 0.0  # when the message of the last step was published
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def step(self, velocities: List[float]) -> float:
        """Send ``velocities`` from the next message on; return when it was published."""
        done = threading.Event()
        with self._lock:
            self._pending = (velocities, done)
        done.wait(1.0)
        return self.step_s

    def _run(self) -> None:
        while not self._stop.is_set():
            with self._lock:
                pending, self._pending = self._pending, None
            if pending is not None:
                self.velocities = pending[0]
            message = JointState(name=self.names, velocity=list(self.velocities))
            sent_s = time.monotonic()
            self.publisher.publish(message)
            if pending is not None:
                self.step_s = sent_s
                pending[1].set()
            self._stop.wait(COMMAND_PERIOD_S)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)
        self.node.destroy_node()


def carries(protocol: str, frame: WireFrame, unit: int, word: int) -> bool:
    """Return whether a master frame writes the run word and reference ``word`` to ``unit``."""
    if protocol == 'modbus_rtu':
        return frame.data[:2] == bytes([unit, 0x0F]) and \
            frame.data == PROFILE.process_write(RUN_WORD, word).frame(unit).encode()
    result = fc_telegram.decode(frame.data)
    telegram = result.telegram
    return (telegram is not None and telegram.adr == fc_telegram.encode_address(unit) and
            telegram.pcd2 == word and telegram.pcd1 == RUN_WORD)


def control_writes(protocol: str, frames: List[WireFrame], unit: int) -> List[WireFrame]:
    """Return the master frames that write a control word and reference to ``unit``."""
    writes = []
    for frame in frames:
        if frame.sender != MASTER:
            continue
        if protocol == 'modbus_rtu':
            if frame.data[:2] == bytes([unit, 0x0F]):
                writes.append(frame)
        else:
            telegram = fc_telegram.decode(frame.data).telegram
            if telegram is not None and telegram.adr == fc_telegram.encode_address(unit):
                writes.append(frame)
    return writes


def wait_for_frames(line: PacedSimulator, protocol: str, words: Dict[int, int],
                    sent_s: float, timeout_s: float = FRAME_TIMEOUT_S) -> Dict[int, float]:
    """Return unit -> start of the first frame after ``sent_s`` carrying its word."""
    found: Dict[int, float] = {}
    deadline = time.monotonic() + timeout_s
    while len(found) < len(words) and time.monotonic() < deadline:
        time.sleep(0.02)
        for frame in line.pacer.frames():
            if frame.sender != MASTER or frame.start_s < sent_s:
                continue
            for unit, word in words.items():
                if unit not in found and carries(protocol, frame, unit, word):
                    found[unit] = frame.start_s
    return found


class CycleLog:
    """The control writes of each drive, from the frame log as it rotates."""

    def __init__(self, protocol: str, units: List[int], timing: LineTiming):
        self.protocol = protocol
        self.units = units
        self.timing = timing
        self.cycles: Dict[Tuple[int, float], float] = {}  # (unit, start) -> since the last
        self.transactions: Dict[Tuple[int, float], float] = {}

    def take(self, frames: List[WireFrame]) -> None:
        """Note the cycles and control-write transactions in ``frames``."""
        for unit in self.units:
            writes = control_writes(self.protocol, frames, unit)
            for earlier, later in zip(writes, writes[1:]):
                self.cycles[(unit, later.start_s)] = later.start_s - earlier.start_s
        for index, frame in enumerate(frames[:-1]):
            if frame.sender == MASTER and frame.data[:1] and any(
                    (unit, frame.start_s) in self.cycles for unit in self.units):
                self.transactions[frame.start_s] = self.timing.transaction_s(
                    len(frame.data), len(frames[index + 1].data))

    def skipped(self, unit: int, sent_s: float, carried_s: float,
                frames: List[WireFrame]) -> bool:
        """Return whether a control write to ``unit`` went out after ``sent_s`` without it."""
        return any(sent_s + MISS_ALLOWANCE_S < write.start_s < carried_s
                   for write in control_writes(self.protocol, frames, unit))


def run(protocol: str, baudrate: int, count: int, steps: int) -> Dict:
    """Run ``steps`` steps on one line; return the latencies and the cycles."""
    blocks = devices(True, count)
    units = [block['address'] for block in blocks.values()]
    timing = LineTiming(baudrate, 'E', 1, gap_characters=GAPS[protocol])
    line = PacedSimulator([f'{b["model"]}:{b["address"]}' for b in blocks.values()], timing,
                          protocol=SIMULATOR_PROTOCOLS[protocol])
    node = NodeProcess({**node_bus(line.path, baudrate), 'protocol': protocol}, blocks)
    chance = random.Random(SEED)
    latencies: List[float] = []
    missing = skipped = 0
    cycles = CycleLog(protocol, units, timing)
    controller = None
    try:
        wait_until_ready(list(blocks))
        controller = Controller(list(blocks))
        start_drives(list(blocks))
        time.sleep(1.0)
        for index in range(steps):
            # Distinct velocities: every step's reference words are new to the line.
            velocities = [2.0 + 0.01 * (index * count + joint) for joint in range(count)]
            words = {unit: PROFILE.reference_word(velocity / SCALE * 100.0)
                     for unit, velocity in zip(units, velocities)}
            sent_s = controller.step(velocities)
            found = wait_for_frames(line, protocol, words, sent_s)
            missing += len(words) - len(found)
            latencies += [started_s - sent_s for started_s in found.values()]
            frames = line.pacer.frames()
            cycles.take(frames)
            skipped += sum(cycles.skipped(unit, sent_s, started_s, frames)
                           for unit, started_s in found.items())
            time.sleep(chance.uniform(*PAUSE_S))
        counters = line.pacer.counters()
    finally:
        if controller is not None:
            controller.close()
        node.stop()
        line.close()
    return {'latencies': latencies, 'missing': missing, 'skipped': skipped,
            'cycles': list(cycles.cycles.values()),
            'transactions': list(cycles.transactions.values()),
            'violations': counters.gap_violations}


def percentile_99(values: List[float]) -> float:
    """Return the 99th percentile of ``values``."""
    return statistics.quantiles(sorted(values), n=100, method='inclusive')[98]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('steps', nargs='?', type=int, default=200)
    parser.add_argument('--configs', nargs='+', default=list(DEFAULT_CONFIGS),
                        metavar='PROTOCOL:BAUD:DRIVES')
    arguments = parser.parse_args()
    print(thread_cpu.machine())
    print(f'FC 51 joints, started, poll_rate 100, 100 Hz commands stepped at random moments, '
          f'through drive_bridge_node on a line paced by the wire pacer (8E1 timing); '
          f'{conditions()}')
    print('| protocol | baud | drives | latencies | p50 ms | p99 ms | max ms | poll cycle ms, '
          'median / p99 | one transaction ms | bound ms | p99 within | within median cycle + '
          'transaction | skipped | no frame | gap violations |')
    print('| --- ' * 15 + '|')
    rclpy.init()
    try:
        for config in arguments.configs:
            protocol, baudrate, count = config.split(':')
            result = run(protocol, int(baudrate), int(count), arguments.steps)
            values = sorted(1000 * value for value in result['latencies'])
            p99 = percentile_99(values)
            cycle, cycle_99 = (statistics.median(result['cycles']) * 1000,
                               percentile_99(result['cycles']) * 1000)
            transaction = statistics.median(result['transactions']) * 1000
            bound = cycle_99 + transaction
            print(f'| {protocol} | {baudrate} | {count} | {len(values)} | '
                  f'{statistics.median(values):.1f} | {p99:.1f} | {values[-1]:.1f} | '
                  f'{cycle:.1f} / {cycle_99:.1f} | {transaction:.1f} | {bound:.1f} | '
                  f'{"yes" if p99 <= bound else "NO"} | '
                  f'{"yes" if p99 <= cycle + transaction else "no"} | {result["skipped"]} | '
                  f'{result["missing"]} | {result["violations"]} |', flush=True)
    finally:
        rclpy.try_shutdown()
    print(thread_cpu.load())


if __name__ == '__main__':
    main()
