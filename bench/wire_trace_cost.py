"""
Benchmark: the CPU a wire trace costs the bus thread, per transaction, off and on.

One Modbus RTU read of 6 registers after another from a simulated MCD 500 on a pty (the
simulator serves from a thread of this process; its CPU is not counted), traced not at all,
to pcapng and to text. The cost is the CPU per transaction of the reading thread (the bus
thread: ``time.thread_time``) and of the trace's writer thread (``pthread_getcpuclockid``),
median and range over ``rounds`` rounds that take the cases in turn; the wall time per
transaction and the trace's bytes per transaction are printed too.
Run: .venv/bin/python bench/wire_trace_cost.py [transactions per round, default 2000]
[rounds, default 5]
"""

import os
import statistics
import sys
import tempfile
import threading
import time
from typing import Dict, List, Optional

from drive_bridge.protocol.requests import ReadRegisters
from drive_bridge.sim.devices import make_sim_server
from drive_bridge.transport.engines import make_transport
from drive_bridge.transport.link import LinkSettings
from drive_bridge.transport.wire_trace import TraceSettings
import thread_cpu

READ = ReadRegisters(2, 6)
CASES = {'off': None, 'pcapng': 'trace.pcapng', 'text': 'trace.txt'}


def writer_cpu_s() -> float:
    """Return the CPU seconds of the trace writer threads there are."""
    return sum(time.clock_gettime(time.pthread_getcpuclockid(thread.ident))
               for thread in threading.enumerate() if thread.name.startswith('wire trace'))


def run_case(port: str, trace_path: Optional[str], count: int) -> tuple:
    """Return (bus thread CPU µs, writer CPU µs, wall µs, trace bytes) per transaction."""
    trace = TraceSettings(trace_path, max_mb=1000.0) if trace_path else None
    transport = make_transport(LinkSettings(port=port, parity='N', timeout_s=0.5), {}, trace)
    transport.connect()
    try:
        transport.execute(20, READ)  # the port opened, the trace's file too
        transport.close()  # what the trace queued is written
        transport.connect()
        writer, cpu, wall = writer_cpu_s(), time.thread_time(), time.perf_counter()
        for _ in range(count):
            transport.execute(20, READ)
        cpu, wall = time.thread_time() - cpu, time.perf_counter() - wall
    finally:
        transport.close()
    writer = writer_cpu_s() - writer
    size = os.path.getsize(trace_path) / (count + 1) if trace_path else 0.0
    return 1e6 * cpu / count, 1e6 * writer / count, 1e6 * wall / count, size


def main() -> None:
    count = int(sys.argv[1]) if len(sys.argv) > 1 else 2000
    rounds = int(sys.argv[2]) if len(sys.argv) > 2 else 5
    print(thread_cpu.machine())
    server = make_sim_server({20: 'mcd500'})
    port = server.open_pty()
    server.start()
    results: Dict[str, List[tuple]] = {name: [] for name in CASES}
    with tempfile.TemporaryDirectory() as directory:
        try:
            for _ in range(rounds):
                for name, file_name in CASES.items():
                    path = os.path.join(directory, file_name) if file_name else None
                    results[name].append(run_case(port, path, count))
                    if path:
                        os.remove(path)
        finally:
            server.stop()
    off = statistics.median(cpu for cpu, _, _, _ in results['off'])
    for name, values in results.items():
        cpus = sorted(cpu for cpu, _, _, _ in values)
        median = statistics.median(cpus)
        writer = statistics.median(writer for _, writer, _, _ in values)
        print(f'trace {name}: bus thread {median:.0f} µs of CPU a transaction [{cpus[0]:.0f}, '
              f'{cpus[-1]:.0f}] ({median - off:+.0f} µs against off), writer thread '
              f'{writer:.0f} µs, wall {statistics.median(w for _, _, w, _ in values):.0f} µs, '
              f'{statistics.median(size for _, _, _, size in values):.0f} bytes of trace a '
              f'transaction; {count} transactions a round, {rounds} rounds')
    print(thread_cpu.load())


if __name__ == '__main__':
    main()
