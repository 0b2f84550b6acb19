"""
Benchmark: FC 51 cycle time at 9600 and 19200 baud, 8E1 timing: Modbus RTU and FC protocol.

One simulated FC 51, started (so the control word and reference go out every cycle), in a
child process, polled as fast as the bus allows through a wire pacer in this process
(:mod:`drive_bridge.sim.wire_pacer`), not the simulator's own reply pacing: every byte takes
its 8E1 wire time, the line is half duplex and every frame must follow its protocol's
silence (Modbus RTU 3.5 characters, FC protocol 2). Over Modbus RTU and over the FC
protocol, for the same drive data (control word, reference, status word,
main actual value, motor current, the slow readouts every ``readout_period``). Prints, from
the pacer's frame log: the cycle time, transactions and bytes per cycle, the wire-time
minimum of the same frames and the fraction of it reached, gap violations and collisions.
Run: .venv/bin/python bench/fc_cycle.py [seconds per case]
"""

import sys
import time

from drive_bridge.bus.events import ReadingEvent
from drive_bridge.bus.master import BusMaster, BusTiming, DeviceSpec
from drive_bridge.devices import fc51
from drive_bridge.devices.contracts import SlowReadouts
from drive_bridge.devices.fc_profile_drive import FcProfileModbusDrive
from drive_bridge.devices.fc_protocol_drive import FcProtocolDriveProfile
from drive_bridge.protocol import fc_telegram as fcp
from drive_bridge.sim.wire_pacer import LineTiming, MODBUS_GAP_CHARACTERS, transactions
from drive_bridge.transport.engines import make_transport
from drive_bridge.transport.link import LinkSettings
from paced_line import PacedSimulator

READOUT_PERIOD_S = 1.0  # the node's default


def make_bus(line: PacedSimulator, protocol: str, readings: list) -> BusMaster:
    """Return a bus master for one FC 51 on ``line`` over ``protocol``."""
    baudrate = line.timing.baudrate
    settings = LinkSettings(protocol=protocol, port=line.path, baudrate=baudrate, parity='N',
                            timeout_s=0.5)  # the pty takes N; the pacer times 8E1
    slow = SlowReadouts(READOUT_PERIOD_S)
    if protocol == 'fc_protocol':
        profile = FcProtocolDriveProfile(fc51.DATA, 'fc51', slow_readouts=slow)
    else:
        profile = FcProfileModbusDrive(fc51.DATA, 'fc51', slow_readouts=slow)
    return BusMaster(make_transport(settings),
                     [DeviceSpec('conv', 1, profile, poll_rate_hz=100.0)],
                     BusTiming(frame_gap_s=line.timing.gap_s),  # the 8E1 gap, not 8N1's
                     listener=lambda event: readings.append(isinstance(event, ReadingEvent)))


def bench(baudrate: int, seconds: float, protocol: str) -> dict:
    """Poll one started FC 51 as fast as the line allows; return the figures."""
    gap = fcp.GAP_CHARACTERS if protocol == 'fc_protocol' else MODBUS_GAP_CHARACTERS
    timing = LineTiming(baudrate, 'E', 1, gap_characters=gap)
    line = PacedSimulator(['fc51:1'], timing,
                          protocol='fc_protocol' if protocol == 'fc_protocol' else 'modbus')
    readings = []
    bus = make_bus(line, protocol, readings)
    deadline = time.monotonic() + 10.0
    while bus.snapshot('conv').reading is None and time.monotonic() < deadline:
        bus.run_step()  # connect, identify, first reading
    started = bus.submit_command('conv', 'start')
    while not started.done() and time.monotonic() < deadline:
        bus.run_step()
    started.result(timeout=0)  # the bench measures a running drive: fail loudly otherwise
    polls_before = sum(readings)
    started = time.monotonic()
    while time.monotonic() - started < seconds:
        bus.run_step()
    ended = time.monotonic()
    polls = sum(readings) - polls_before
    bus.shutdown(stop_motors=False)
    frames = [frame for frame in line.pacer.frames()
              if started <= frame.start_s and frame.end_s <= ended]
    pairs = transactions(frames)
    wire_s = sum(timing.transaction_s(len(request.data), len(reply.data))
                 for request, reply in pairs)
    counters = line.pacer.counters()
    line.close()
    return {'cycle_ms': 1000 * (ended - started) / polls, 'tx_per_cycle': len(pairs) / polls,
            'bytes_per_cycle': sum(len(request.data) + len(reply.data)
                                   for request, reply in pairs) / polls,
            'wire_ms': 1000 * wire_s / polls, 'violations': counters.gap_violations,
            'collisions': counters.collisions}


def main() -> None:
    seconds = float(sys.argv[1]) if len(sys.argv) > 1 else 5.0
    print(f'1 simulated FC 51 running, 8E1 timing through the wire pacer, readout_period '
          f'{READOUT_PERIOD_S:g} s, {seconds:g} s per case')
    print('protocol      baud  cycle ms  tx/cycle  bytes/cycle  wire ms/cycle  '
          'fraction  cycles/s  gap viol.  collisions')
    for baudrate in (9600, 19200):
        for protocol in ('modbus_rtu', 'fc_protocol'):
            result = bench(baudrate, seconds, protocol)
            print(f'{protocol:11s}  {baudrate:5d}  {result["cycle_ms"]:8.1f}  '
                  f'{result["tx_per_cycle"]:8.2f}  {result["bytes_per_cycle"]:11.1f}  '
                  f'{result["wire_ms"]:13.1f}  {result["wire_ms"] / result["cycle_ms"]:8.1%}  '
                  f'{1000 / result["cycle_ms"]:8.1f}  {result["violations"]:9d}  '
                  f'{result["collisions"]:10d}')


if __name__ == '__main__':
    main()
