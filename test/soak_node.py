"""
The soak through the node: ``drive_bridge_node`` in a subprocess on the soak's line.

The same simulated line as the bus soak (:mod:`soak_harness.runner`: two MCD starters,
two drives, an MCD 202 behind a gateway, a monitor-only FC 51, a dead address), with faults,
outages and trips, served from this process on a pty. An rclpy client calls the devices'
Trigger services at random, several calls in flight at once (one per device), publishes
speed references (some invalid) on ``<dev>/speed_reference``, and records what it asked,
what each reply said and the ``<dev>/state`` it was told (offline, tripped). The run ends
with SIGTERM: the node must stop every motor that may run because of it, except the
devices with ``stop_on_shutdown: false`` (the MCD 3000 here), which get no write after it.

The oracle (:mod:`soak_harness.oracle`) checks the line's log against that record.
Answers and states travel through ROS, so they are placed when the client received them
(the oracle's non-exact mode). Used by ``test/ros/test_soak_node.py`` and
``bench/soak_node.py``.
"""

from collections import Counter
from dataclasses import dataclass, field, replace
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
from typing import Dict, List, Optional, Tuple

from drive_bridge.sim.faults import FaultPlan
import rclpy
from rclpy.qos import DurabilityPolicy, QoSProfile
from ros_helpers import node_output, start_node, write_params
from soak_harness.oracle import (
    as_float32, ClientLog, Oracle, outcome_of_reply, Request, summarize, Violation,
    VIOLATION_KINDS)
from soak_harness.runner import (
    commands_for, Disturbances, LINE, line_config, LineDevice, make_line, random_reference,
    running_motors)
from std_msgs.msg import Float32, String
from std_srvs.srv import Trigger

LATCHED = QoSProfile(depth=10, durability=DurabilityPolicy.TRANSIENT_LOCAL)
SERVICES = {'mcd': ('start', 'stop', 'quick_stop', 'reset'),
            'drive': ('start', 'stop', 'quick_stop', 'coast_stop', 'reset'),
            'lvsg': ('start', 'stop', 'quick_stop', 'reset')}
LEFT_RUNNING = 'press'  # stop_on_shutdown: false
PATCHED_NODE = os.path.join(os.path.dirname(os.path.abspath(__file__)), 'soak_patched_node.py')


def node_line() -> Tuple[LineDevice, ...]:
    """Return the soak line with ``press`` left running at shutdown."""
    return tuple(replace(device, values=dict(device.values, stop_on_shutdown=False))
                 if device.name == LEFT_RUNNING else device for device in LINE)


@dataclass
class NodeSoakSettings:
    """What to run through the node."""

    duration_s: float = 60.0
    fault_rate: float = 0.1
    seed: int = 1
    timeout_s: float = 0.2
    poll_rate_hz: float = 50.0
    command_period_s: float = 0.05
    max_in_flight: int = 4  # calls waiting for their reply at once (one per device)
    outage_period_s: float = 6.0
    outage_s: Tuple[float, float] = (1.0, 2.5)
    trip_period_s: float = 8.0
    invalid_reference_share: float = 0.1
    lvsg_quick_stop: bool = True  # quick stops to the gateway too
    broken: str = ''  # run the node broken on purpose (soak_broken.VARIANTS)


@dataclass
class NodeSoakReport:
    """What the node soak saw; the zeros are the pass criteria."""

    duration_s: float = 0.0
    transactions: int = 0  # requests the line carried
    commands: Counter = field(default_factory=Counter)
    references: int = 0
    injected: Counter = field(default_factory=Counter)  # fault kind -> count
    silenced: int = 0  # requests to a device during its outage
    outages: int = 0
    trips: int = 0
    offline_notices: int = 0
    violations: List[Violation] = field(default_factory=list)
    unanswered: int = 0  # calls that never got a reply
    unanswered_calls: List[str] = field(default_factory=list)
    final_starts: Dict[str, str] = field(default_factory=dict)  # device -> outcome
    left_running: str = ''  # what runs at the stop_on_shutdown: false device afterwards
    exit_code: Optional[int] = None
    shutdown_s: float = 0.0  # SIGTERM to exit
    output: str = ''

    @property
    def passed(self) -> bool:
        """Return whether the run meets its criteria."""
        return self.exit_code == 0 and not self.violations and not self.unanswered

    def lines(self, most: int = 20) -> List[str]:
        """Return the report as printable lines."""
        counts = summarize(self.violations)
        lines = [f'line requests: {self.transactions} in {self.duration_s:.1f} s',
                 'calls: ' + ', '.join(f'{key} {count}'
                                       for key, count in sorted(self.commands.items())),
                 f'speed references published: {self.references}',
                 'faults injected: ' + ', '.join(f'{kind} {count}' for kind, count
                                                 in sorted(self.injected.items()))
                 + f'; requests during outages {self.silenced}',
                 f'outages {self.outages}, trips {self.trips}, offline states '
                 f'{self.offline_notices}',
                 f'calls never answered: {self.unanswered}'
                 + ''.join(f'; {call}' for call in self.unanswered_calls),
                 'started before SIGTERM: ' + ', '.join(
                     f'{name} {outcome}' for name, outcome in sorted(self.final_starts.items())),
                 f'{LEFT_RUNNING} (stop_on_shutdown false) afterwards: '
                 f'{self.left_running or "stopped"}',
                 f'SIGTERM to exit: {self.shutdown_s:.2f} s, exit code {self.exit_code}',
                 f'violations: {len(self.violations)}']
        lines += [f'  {kind:24s} {counts[kind]:6d}  ({text})'
                  for kind, text in VIOLATION_KINDS.items() if counts[kind]]
        lines += [f'  - {violation.line()}' for violation in self.violations[:most]]
        lines.append('PASS' if self.passed else 'FAIL')
        return lines


class _Client:
    """The rclpy side: service calls, speed references, and the states it is told."""

    def __init__(self, devices: Tuple[LineDevice, ...], log: ClientLog, namespace: str):
        self.devices = devices
        self.log = log
        self.node = rclpy.create_node(f'soak_client_{os.getpid()}')
        self.offline: Dict[str, bool] = {}
        self.calls = {(device.name, command): self.node.create_client(
            Trigger, f'{namespace}/{device.name}/{command}')
            for device in devices for command in SERVICES[device.kind]}
        self.references = {device.name: self.node.create_publisher(
            Float32, f'{namespace}/{device.name}/speed_reference', 10)
            for device in devices if device.kind == 'drive'}
        self.states: Dict[str, str] = {}
        for device in devices:
            self.node.create_subscription(
                String, f'{namespace}/{device.name}/state',
                lambda message, name=device.name: self._on_state(name, message.data), LATCHED)
        self.pending: List[Tuple[Request, object]] = []

    def _on_state(self, name: str, state: str) -> None:
        self.states[name] = state
        if state == 'offline':
            if not self.offline.get(name):
                self.log.notice(name, 'offline')
            self.offline[name] = True
            return
        if self.offline.get(name):
            self.log.notice(name, 'online')
            self.offline[name] = False
        if state == 'tripped':
            self.log.notice(name, 'tripped')

    def wait_for_services(self, timeout_s: float) -> bool:
        """Wait until every service is there."""
        deadline = time.monotonic() + timeout_s
        return all(client.wait_for_service(timeout_sec=max(0.1, deadline - time.monotonic()))
                   for client in self.calls.values())

    def call(self, name: str, command: str) -> Request:
        """Call ``name/command`` (the reply is collected by :meth:`collect`)."""
        request = self.log.ask(name, command)
        future = self.calls[(name, command)].call_async(Trigger.Request())
        self.pending.append((request, future))
        return request

    def collect(self) -> None:
        """Record the replies that arrived."""
        waiting = []
        for request, future in self.pending:
            if future.done():
                response = future.result()
                self.log.answer(request, outcome_of_reply(response.success, response.message),
                                response.message)
            else:
                waiting.append((request, future))
        self.pending = waiting

    def publish_reference(self, name: str, percent: float) -> None:
        """Publish a speed reference and record it (as Float32 carries it)."""
        value = as_float32(percent)
        self.log.reference(name, value, None)
        self.references[name].publish(Float32(data=value))

    def spin(self, timeout_s: float = 0.005) -> None:
        """Serve the client's callbacks once and collect replies."""
        rclpy.spin_once(self.node, timeout_sec=timeout_s)
        self.collect()

    def spin_until(self, predicate, timeout_s: float) -> bool:
        """Spin until ``predicate()`` or the timeout; return its last value."""
        deadline = time.monotonic() + timeout_s
        while not predicate() and time.monotonic() < deadline:
            self.spin(0.05)
        return bool(predicate())

    def close(self) -> None:
        """Destroy the client's node."""
        self.node.destroy_node()


class _Driver:
    """Random calls and references, several calls in flight, one per device."""

    def __init__(self, client: _Client, settings: NodeSoakSettings):
        self.client = client
        self.settings = settings
        self.random = random.Random(settings.seed + 1)
        self.commands = commands_for(settings.lvsg_quick_stop)
        self.next_s = time.monotonic()
        self.references = 0

    def step(self) -> None:
        """Maybe make a call or publish a reference."""
        now = time.monotonic()
        if now < self.next_s:
            return
        self.next_s = now + self.settings.command_period_s
        device = self.random.choice(self.client.devices)
        if self.client.offline.get(device.name) and self.random.random() < 0.8:
            return
        if device.kind == 'drive' and self.random.random() < 0.3:
            self.client.publish_reference(
                device.name, random_reference(self.random,
                                              self.settings.invalid_reference_share))
            self.references += 1
            return
        busy = {request.device for request, _ in self.client.pending}
        if device.name in busy or len(busy) >= self.settings.max_in_flight:
            return
        self.client.call(device.name, self.random.choice(self.commands[device.kind]))


def start_broken_node(params_file: str, variant: str, namespace: str) -> subprocess.Popen:
    """Start the node broken as ``variant`` says (soak_patched_node.py), as start_node does."""
    log = tempfile.NamedTemporaryFile('w+', prefix='drive_bridge_node_', suffix='.log')
    process = subprocess.Popen(
        [sys.executable, PATCHED_NODE, variant, '--ros-args', '--params-file', params_file,
         '-r', f'__ns:={namespace}'], env=dict(os.environ), stdout=log, stderr=log, text=True)
    process.log = log
    return process


def run_node_soak(settings: NodeSoakSettings, directory: str) -> NodeSoakReport:
    """Run the node on the soak line for ``settings.duration_s``, SIGTERM it, check it."""
    devices = node_line()
    server = make_line(settings.fault_rate, settings.seed, 0.7 * settings.timeout_s,
                       settings.timeout_s, devices=devices)
    port = server.open_pty()
    server.start()
    report = NodeSoakReport()
    log = ClientLog(lambda: server.seq)
    # A namespace of its own: another process in the same ROS domain (a test run beside
    # this one) may have devices of the same names.
    namespace = f'/soak{os.getpid()}'
    client = _Client(devices, log, namespace)
    bus, values = line_config(port, settings.timeout_s, settings.poll_rate_hz, devices)
    params = write_params(os.path.join(directory, 'soak.yaml'), bus, values)
    process = start_broken_node(params, settings.broken, namespace) if settings.broken else \
        start_node(params, namespace)
    disturbances = Disturbances(server, time.monotonic, random.Random(settings.seed + 2),
                                settings.outage_period_s, settings.outage_s,
                                settings.trip_period_s, devices)
    try:
        _run(client, settings, disturbances, report)
        final_states = _shut_down(server, client, log, disturbances, process, report)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
        report.output = node_output(process)
        client.close()
        server.stop()
    report.transactions = server.seq
    report.injected = server.faults.totals()
    report.silenced = sum(frame.silenced for frame in server.frames)
    report.commands = log.outcomes()
    report.outages, report.trips = disturbances.outages, disturbances.trips
    report.offline_notices = sum(notice.kind == 'offline' for notice in log.notices)
    report.violations = Oracle(server.frames, log, [device.info for device in devices]) \
        .check(final_states)
    return report


def _run(client: _Client, settings: NodeSoakSettings, disturbances: Disturbances,
         report: NodeSoakReport) -> None:
    if not client.wait_for_services(30.0):
        raise RuntimeError('the node did not offer its services within 30 s')
    driver = _Driver(client, settings)
    started = time.monotonic()
    while time.monotonic() - started < settings.duration_s:
        client.spin()
        disturbances.step()
        driver.step()
    report.duration_s = time.monotonic() - started
    report.references = driver.references


def _shut_down(server, client: _Client, log: ClientLog, disturbances: Disturbances,
               process, report: NodeSoakReport) -> Dict[str, str]:
    """End outages and faults, let the calls be answered, SIGTERM the node."""
    disturbances.end()
    plan = server.faults.plan
    server.faults.set_plan(FaultPlan(0.0, plan.kinds, plan.seed, slow_s=plan.slow_s))
    _wait_for_replies(client, 15.0)
    report.unanswered = len(client.pending)
    report.unanswered_calls = [f'{request.device}/{request.command} asked at '
                               f'{request.asked_s - log.started_s:.3f} s'
                               for request, _ in client.pending]
    # Something to stop: every device the node controls is reset and started once more.
    client.spin_until(lambda: not any(client.offline.values()), 15.0)
    controlled = [device.name for device in client.devices
                  if device.model and device.values.get('allow_control', True)]
    for command in ('reset', 'start'):
        asked = [client.call(name, command) for name in controlled]
        _wait_for_replies(client, 15.0)
    report.final_starts = {request.device: request.outcome for request in asked}
    log.shutdown(ends_runs=False)  # the node takes the signal a moment later
    signalled = time.monotonic()
    process.send_signal(signal.SIGTERM)
    try:
        report.exit_code = process.wait(timeout=30.0)
    except subprocess.TimeoutExpired:
        report.exit_code = None  # a node that does not exit fails the run
    report.shutdown_s = time.monotonic() - signalled
    log.shutdown()
    states = running_motors(server, client.devices)
    report.left_running = states.get(LEFT_RUNNING, '')
    return states


def _wait_for_replies(client: _Client, timeout_s: float) -> None:
    deadline = time.monotonic() + timeout_s
    while client.pending and time.monotonic() < deadline:
        client.spin(0.05)
