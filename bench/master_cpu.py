"""
Benchmark: the node's CPU per transaction beside a C master's (libmodbus), on the same line.

Per baud rate, in one run: ``drive_bridge_node`` polls 4 MCD 500 and 4 FC 51 at 100 Hz on a
line paced by the wire pacer (as ``node_cpu.py``, no subscriber), then a libmodbus RTU
master (``libmodbus_master.c``, built here with the system's ``cc`` and Debian's
``libmodbus-dev``) sends the same requests, a stretch of the node's own as the wire log
holds them, in turn as fast as the line answers (sleeping the 3.5-character gap after each
reply, which libmodbus does not keep by itself), to the same simulated devices on a fresh
line of the same timing. Both are measured over the same window from the scheduler's
accounting (whole process, every thread) and the pacer's frame log: transactions a second,
CPU per transaction, the wire fraction (the transactions' wire time, gaps included, over the
window). The ratio is the node's CPU per transaction over the peer's: the goal of issue 43
is 1.0 or less. The C peer is skipped, saying what to install, where ``cc`` or libmodbus is
missing. A second peer, ``python_master.py``, is a minimal CPython master (one write, one
wait, one read and the gap a transaction; only the reply's length and CRC checked) on the
same line and requests: its ratio to libmodbus is what CPython itself costs, the node's ratio
to it what the package's own code costs.
Run: .venv/bin/python bench/master_cpu.py [window seconds] [--baud 19200 --baud 115200]
[--runs 1] [--compare LABEL=DIR ...]
"""

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from typing import Dict, List, Optional

from drive_bridge.sim.wire_pacer import LineTiming
import node_cpu
from paced_line import conditions, LINE_DEVICES, PacedSimulator, simulator_devices, versions
import rclpy
import thread_cpu

HERE = os.path.dirname(os.path.abspath(__file__))
SOURCE = os.path.join(HERE, 'libmodbus_master.c')
PYTHON_FLOOR = [sys.executable, os.path.join(HERE, 'python_master.py')]
REPLAYED = 64  # requests of the node's the peer sends in turn (at most 64: the helper's)
BAUDRATES = (19200, 115200)


def build_peer(directory: str) -> Optional[str]:
    """Build the C master in ``directory``; return its path, or None after saying why not."""
    compiler = shutil.which('cc') or shutil.which('gcc')
    if compiler is None:
        print('peer skipped: no C compiler (apt install gcc libmodbus-dev)')
        return None
    flags = ['-I/usr/include/modbus', '-lmodbus']
    if shutil.which('pkg-config'):
        found = subprocess.run(['pkg-config', '--cflags', '--libs', 'libmodbus'],
                               capture_output=True, text=True)
        if found.returncode == 0:
            flags = found.stdout.split()
    binary = os.path.join(directory, 'libmodbus_master')
    built = subprocess.run([compiler, '-O2', '-o', binary, SOURCE, *flags],
                           capture_output=True, text=True)
    if built.returncode != 0:
        said = built.stderr.strip().splitlines()
        print('peer skipped: libmodbus_master.c does not build (apt install libmodbus-dev)' +
              (f': {said[-1]}' if said else ''))
        return None
    return binary


def measure_peer(command: List[str], requests: List[bytes], window_s: float,
                 baudrate: int) -> Dict:
    """Run a peer master on a fresh paced line with ``requests`` (CRCs cut) for one window."""
    timing = LineTiming(baudrate, 'E', 1)
    line = PacedSimulator(simulator_devices(LINE_DEVICES), timing)
    gap_us = str(round(timing.gap_s * 1e6))
    peer = subprocess.Popen([*command, line.path, str(baudrate), 'N', '2', gap_us,
                             *(request[:-2].hex() for request in requests)],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        said = peer.stdout.readline().strip()
        if said != 'ready':
            raise RuntimeError(f'{command[-1]} did not start: {said}')
        time.sleep(node_cpu.WARM_UP_S)
        window = thread_cpu.measure_window(peer.pid, window_s)
        wire = line.wire_figures(window.started_s, window.ended_s)
    finally:
        peer.terminate()
        output, _ = peer.communicate(timeout=10)
        line.close()
    rows = window.shares({})
    return {'total': thread_cpu.total_pct(rows), 'wire': wire, 'said': output.strip()}


def per_transaction_us(result: Dict) -> float:
    """Return CPU microseconds per transaction on the wire (whole process)."""
    rate = result['wire']['rate']
    return result['total'] / 100.0 / rate * 1e6 if rate else float('nan')


def describe(label: str, result: Dict) -> str:
    """Return one measurement in one line."""
    wire = result['wire']
    return (f'  {label:26s} {wire["rate"]:7.1f} tx/s  {per_transaction_us(result):6.0f} us '
            f'CPU a transaction  {result["total"]:5.2f} % of a core  wire '
            f'{wire["fraction"]:.1%}')


def frame_sizes(requests: List[bytes]) -> str:
    """Return the replayed requests' mix in words."""
    functions = sorted({request[1] for request in requests})
    return (f'{len(requests)} requests of the node, functions ' +
            ', '.join(f'0x{code:02x}' for code in functions) +
            f', {statistics.mean(len(request) for request in requests):.1f} bytes on average')


def run_peers(binary: Optional[str], node_runs: List, window_s: float, baudrate: int,
              ratios: Dict[str, List[float]]) -> None:
    """Run the peers on the node's requests; print each and add the ratios to ``ratios``."""
    requests = node_runs[0][1]['requests'][-REPLAYED:]
    peers = [('libmodbus', 'libmodbus 3.1 master (C)', [binary])] if binary else []
    peers.append(('Python floor', 'Python floor (length, CRC)', PYTHON_FLOOR))
    measured = []
    for short, long, command in peers:
        measured.append((short, measure_peer(command, requests, window_s, baudrate)))
        print(describe(long, measured[-1][1]) + f'  ({measured[-1][1]["said"]})')
        for label, result in node_runs:
            add_ratio(ratios, f'{baudrate} node{" " + label if label else ""} / {short}',
                      result, measured[-1][1])
    if len(measured) == 2:
        add_ratio(ratios, f'{baudrate} Python floor / libmodbus', measured[1][1],
                  measured[0][1])
    print(f'    replayed: {frame_sizes(requests)}')


def add_ratio(ratios: Dict[str, List[float]], key: str, over: Dict, under: Dict) -> None:
    """Print and keep the ratio of two measurements' CPU a transaction under ``key``."""
    ratio = per_transaction_us(over) / per_transaction_us(under)
    ratios.setdefault(key, []).append(ratio)
    print(f'    ratio {key.split(" ", 1)[1]}, CPU a transaction: {ratio:.2f}')


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('window_s', nargs='?', type=float, default=10.0)
    parser.add_argument('--baud', type=int, action='append', dest='baudrates',
                        help='baud rate (repeatable; default 19200 and 115200)')
    parser.add_argument('--runs', type=int, default=1, help='measurements of each, afresh')
    parser.add_argument('--compare', action='append', default=[], metavar='LABEL=DIR',
                        help='run the drive_bridge package in DIR (LABEL= alone: the '
                        'installed one), the versions in turn; repeatable')
    arguments = parser.parse_args()
    print(thread_cpu.machine())
    print(f'4 MCD 500 + 4 FC 51 at 100 Hz, 8E1 timing through the wire pacer, no subscriber; '
          f'{conditions()}')
    directory = tempfile.mkdtemp(prefix='drive_bridge_peer_')
    binary = build_peer(directory)
    rclpy.init()
    ratios: Dict[str, List[float]] = {}
    try:
        for baudrate in arguments.baudrates or BAUDRATES:
            for index in range(arguments.runs):
                print(f'{baudrate} baud, run {index + 1}:')
                node_runs = []
                for label, source in versions(arguments.compare):
                    node_runs.append((label, node_cpu.measure(
                        arguments.window_s, baudrate, [], 0.0, source)))
                    print(describe(f'drive_bridge_node {label}'.strip(), node_runs[-1][1]))
                run_peers(binary, node_runs, arguments.window_s, baudrate, ratios)
    finally:
        rclpy.try_shutdown()
        shutil.rmtree(directory, ignore_errors=True)
    for key, values in ratios.items():
        print(f'ratio at {key}: median {statistics.median(values):.2f} over {len(values)} '
              f'run(s) [{min(values):.2f}, {max(values):.2f}]')
    print(thread_cpu.load())


if __name__ == '__main__':
    sys.exit(main())
