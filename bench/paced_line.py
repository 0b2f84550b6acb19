"""
Bench helpers: a simulator in a child process behind a wire pacer in the bench process.

The simulator (``drive_bridge_sim``) runs in its own process so that it does not share the
bench's interpreter lock with the pacer; the pacer runs here so that its frame log and the
bench's clock are one clock (``time.monotonic``). :class:`NodeProcess` runs the real
``drive_bridge_node`` on the pacer's pty with a params file, as the ROS tests do.
"""

import os
import signal
import subprocess
import sys
import tempfile
import time
from typing import Dict, List, Sequence, Tuple

from drive_bridge.config.params_file import write_params_file
from drive_bridge.sim.wire_pacer import (
    LineTiming, transactions, wire_fraction, WireFrame, WirePacer)

TEST_DIR = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), 'test')


def ros_environment() -> None:
    """Set what the node and an rclpy client need: loopback discovery, a domain of its own."""
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    os.environ.setdefault('ROS_DOMAIN_ID', str(200 + os.getpid() % 30))
    os.environ.setdefault('AMENT_PREFIX_PATH', sys.prefix)
    os.environ.setdefault('FASTRTPS_DEFAULT_PROFILES_FILE',
                          os.path.join(TEST_DIR, 'fastdds_test_profile.xml'))


class PacedSimulator:
    """
    ``drive_bridge_sim`` serving ``devices`` (MODEL:ADDRESS) behind a pacer at ``path``.

    The pacer's slave is ideal (its reply goes on the wire exactly one gap after the request):
    the wire limit assumes no processing time in the slave, so the figures measure the master,
    not the simulator's process behind its pty.
    """

    def __init__(self, devices: Sequence[str], timing: LineTiming, protocol: str = 'modbus'):
        self.timing = timing
        command = [sys.executable, '-m', 'drive_bridge.sim.cli', '--protocol', protocol]
        for device in devices:
            command += ['--device', device]
        self.process = subprocess.Popen(command, stdin=subprocess.DEVNULL,
                                        stdout=subprocess.PIPE, text=True)
        pty_path = self._wait_for_pty()
        self.pacer = WirePacer(timing, ideal_slave=True)  # the simulator's time not counted
        self.path = self.pacer.open_pty(pty_path)
        self.pacer.start()

    def _wait_for_pty(self) -> str:
        pty_path = ''
        for line in self.process.stdout:
            if line.startswith('pty: '):
                pty_path = line.split(': ', 1)[1].strip()
            if line.startswith('ready: '):
                return pty_path
        raise RuntimeError(f'the simulator exited with {self.process.wait()}')

    def transactions(self, started_s: float, ended_s: float) -> List[Tuple[WireFrame, WireFrame]]:
        """Return the (request, reply) pairs whose frames lie wholly within a window."""
        return transactions([frame for frame in self.pacer.frames()
                             if started_s <= frame.start_s and frame.end_s <= ended_s])

    def wire_figures(self, started_s: float, ended_s: float) -> Dict[str, float]:
        """Return what the frame log shows in a window: transactions/s, wire fraction, limit."""
        pairs = self.transactions(started_s, ended_s)
        seconds = ended_s - started_s
        fraction = wire_fraction(pairs, self.timing, seconds)
        rate = len(pairs) / seconds
        return {'rate': rate, 'fraction': fraction,
                'limit': rate / fraction if fraction else 0.0}

    def requests(self, started_s: float, ended_s: float) -> List[bytes]:
        """Return the requests of the transactions in a window, oldest first, with CRCs."""
        return [request.data for request, _ in self.transactions(started_s, ended_s)]

    def close(self) -> None:
        """Stop the pacer and the simulator."""
        self.pacer.stop()
        self.process.send_signal(signal.SIGTERM)
        try:
            self.process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
        self.process.stdout.close()


class NodeProcess:
    """``drive_bridge_node`` in a subprocess with a params file for ``bus`` and ``devices``."""

    def __init__(self, bus: Dict, devices: Dict[str, Dict],
                 main: Sequence[str] = ('-m', 'drive_bridge.ros.node.entry'), source: str = ''):
        """
        Start the node; ``main``: the interpreter arguments that run it.

        ``source``: a directory holding another ``drive_bridge`` package (a checkout or an
        export of another commit) for the node to run instead of the installed one, to
        compare two versions on one machine (``--compare`` of the CPU benches).
        """
        self.directory = tempfile.TemporaryDirectory(prefix='drive_bridge_bench_')
        params = write_params_file(os.path.join(self.directory.name, 'bus.yaml'), bus, devices)
        self.log = open(os.path.join(self.directory.name, 'node.log'), 'w+')
        environment = dict(os.environ)
        if source:  # first on the path: the directory it runs in, and PYTHONPATH
            source = os.path.abspath(source)
            environment['PYTHONPATH'] = os.pathsep.join(
                filter(None, [source, environment.get('PYTHONPATH', '')]))
        self.process = subprocess.Popen(
            [sys.executable, *main, '--ros-args', '--params-file', params],
            env=environment, cwd=source or None, stdout=self.log, stderr=self.log, text=True)

    @property
    def pid(self) -> int:
        return self.process.pid

    def output(self) -> str:
        """
        Return what the node printed so far.

        Through an open file of its own: a ``seek(0)`` on ``self.log``, whose file offset the
        node's descriptors share, would make the node's next line overwrite the log's start.
        """
        with open(self.log.name) as log:
            return log.read()

    def stop(self) -> int:
        """SIGTERM the node; return its exit code."""
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
        try:
            self.process.wait(timeout=15)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
        self.log.close()
        self.directory.cleanup()
        return self.process.returncode


# 4 MCD 500 and 4 FC 51 on one line, each polled as fast as the node allows (100 Hz).
LINE_DEVICES: Dict[str, Dict] = {
    **{f'mcd{unit}': {'family': 'mcd', 'model': 'mcd500', 'address': unit, 'poll_rate': 100.0}
       for unit in (20, 21, 22, 23)},
    **{f'fc{unit}': {'family': 'fc', 'model': 'fc51', 'address': unit, 'poll_rate': 100.0}
       for unit in (1, 2, 3, 4)},
}


def simulator_devices(devices: Dict[str, Dict]) -> List[str]:
    """Return the simulator's MODEL:ADDRESS arguments for a node's device blocks."""
    return [f'{block["model"]}:{block["address"]}' for block in devices.values()]


def node_bus(path: str, baudrate: int) -> Dict:
    """Return the node's bus settings on the pacer's pty: parity N, 8N2 (11 bits as 8E1)."""
    return {'port': path, 'baudrate': baudrate, 'parity': 'N', 'timeout': 0.5}


def versions(compare: Sequence[str]) -> List[Tuple[str, str]]:
    """
    Return (label, source) of each version to run: the installed package, or ``--compare``'s.

    ``compare`` holds ``LABEL=DIRECTORY`` items (a directory with a ``drive_bridge``
    package, e.g. ``git archive <commit> drive_bridge | tar -x -C DIRECTORY``); ``LABEL=``
    alone is the installed package.
    """
    if not compare:
        return [('', '')]
    pairs = []
    for item in compare:
        label, _, source = item.partition('=')
        if source and not os.path.isdir(os.path.join(source, 'drive_bridge')):
            raise SystemExit(f'--compare {item}: no drive_bridge package in {source}')
        pairs.append((label, source))
    return pairs


def conditions() -> str:
    """Return what of the environment changes the node's CPU (message field checks)."""
    checks = os.environ.get('ROS_PYTHON_CHECK_FIELDS', '') not in ('', '0')
    return f'ROS_PYTHON_CHECK_FIELDS {"on" if checks else "off"}'


def wait_for(predicate, timeout_s: float, interval_s: float = 0.05) -> bool:
    """Poll ``predicate`` until true or the timeout; return its last value."""
    deadline = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > deadline:
            return False
        time.sleep(interval_s)
    return True
