"""
Soak of one mixed RS-485 bus against the simulators, checked by an independent oracle.

One simulated Modbus RTU line carries an MCD 500 and an MCD 3000 (soft starters), an FC 51
and a VLT 5000 (drives), a Profibus gateway with an MCD 202 behind it, a monitor-only FC 51
(``allow_control`` false) and one configured address nobody answers. The simulator spoils a
share of the replies (every kind in :mod:`drive_bridge.sim.faults`); now and then a device
goes silent for a while (an outage: the bridge reports it offline, then online) or trips
(an alarm at the device). A driver sends random commands, speed references (some of them
invalid) and commands at the monitor-only and the dead device through the bus master, as
the ROS node does, and records what it asked and what it was told. At the end the faults
stop and the bridge stops everything (the shutdown's stop of every motor).

The oracle (:mod:`soak_harness.oracle`) then checks the safety invariants from the
line's log (what each device received and executed) and the driver's record alone; the fault
counts by kind are compared with the bus statistics. Figures: :class:`SoakReport`.

The line is a pty with the bridge's serial transport in real time, or a virtual line on a
virtual clock (:mod:`soak_harness.line`): the same seed gives the same run, however
loaded the machine. No ROS: the bus master runs in the driver's thread (``run_once``), so
the driver's record of every answer is exact. The node tier is ``test/soak_node.py``.
"""

from collections import Counter
from dataclasses import dataclass, field, replace
import functools
import math
import random
import time
from typing import Callable, Dict, List, Optional, Tuple

from drive_bridge.bus.events import (
    BusEvent, DeviceOffline, DeviceOnline, handler_table, ignore, Notice, ReadingEvent,
    StateUnknown)
from drive_bridge.bus.master import BusMaster
from drive_bridge.config.model import BridgeConfig, build_config, keepalive_gaps
from drive_bridge.errors import CommandRefused
from drive_bridge.protocol import fc_profile
from drive_bridge.sim.devices import make_device
from drive_bridge.sim.faults import FaultPlan, MODBUS_FAULTS
from drive_bridge.sim.fc_profile_model import ALARM_OVER_CURRENT, TIMEOUT_STOP
from drive_bridge.sim.lvsg_gateway import LvsgGatewaySim, LvsgSlave
from drive_bridge.sim.mcd_model import McdModel, McdSimConfig, RUNNING, STARTING
from drive_bridge.transport.serial_rtu import RtuSerialTransport
from soak_harness.line import RecordingServer, VirtualClock, VirtualLine
from soak_harness.oracle import (
    ClientLog, DeviceInfo, Oracle, summarize, Violation, VIOLATION_KINDS)

# The bus statistics' failure kind -> the injected fault kinds it must count, exactly. A reply
# that never came in its window is a timeout: no reply at all, a late one (after the timeout:
# read and discarded in the quarantine), and a request during an outage.
COUNTED_AS = {'crc': ('crc',), 'timeout': ('no_reply', 'late'), 'slow': ('slow',),
              'exception': ('exception',), 'bad_frame': ('garbage',),
              'truncated': ('truncated',), 'wrong_address': ('wrong_address',)}
# Every fault kind but 'late_batched' is drawn at random. A reply held until the next request
# is told from that request's answer only by coming with it (two frames in one window, or one
# that does not fit): drawn at random, the next request's own reply may be lost to another
# fault or an outage, and a held reply of the same shape is then all that window gets, which
# no rule can tell from its answer on a pty (docs/reliability.md, "What no rule can tell").
# The held replies are tested where the next answer comes (test_late_reply.py, the node's).
SOAK_FAULTS = tuple(kind for kind in MODBUS_FAULTS if kind != 'late_batched')
LVSG_OUTPUT_REGISTER = 100
COMMANDS = {
    'mcd': ('start', 'start', 'stop', 'stop', 'quick_stop', 'reset'),
    'drive': ('start', 'start', 'stop', 'stop', 'quick_stop', 'coast_stop', 'reset'),
    'lvsg': ('start', 'start', 'stop', 'stop', 'quick_stop', 'reset'),
}

INVALID_REFERENCES = (math.nan, math.inf, -math.inf, 250.0, -300.0, 200.0)
MCD_TRIPS = (1, 2, 4, 7)  # excess start time, motor overload, current imbalance, overcurrent
SIM_SETTINGS = {'mcd': {'start_time_s': 0.5, 'stop_time_s': 0.5},
                'drive': {'ramp_up_s': 0.5, 'ramp_down_s': 0.5}}


@dataclass(frozen=True)
class LineDevice:
    """One device of the soak line: its configuration, simulated model and kind."""

    name: str
    values: Dict  # the device's settings, as in a params file
    model: str  # simulated model ('' : nobody answers)
    kind: str  # 'mcd', 'drive' or 'lvsg' (see soak_line.KINDS)

    @property
    def unit(self) -> int:
        """Return the device's address."""
        return self.values['address']

    @property
    def info(self) -> DeviceInfo:
        """Return what the oracle knows of the device: its configuration."""
        return DeviceInfo(self.name, self.unit, self.kind,
                          monitor_only=not self.values.get('allow_control', True),
                          stop_on_shutdown=self.values.get('stop_on_shutdown', True),
                          reference_pct=self.values.get('speed_reference', 0.0))


# A placeholder: line_config sets each drive's comms_timeout to what the keepalive rule
# advises for the soak's timeout and poll rate (its gap and the margin), as a user would.
SOAK_COMMS_TIMEOUT_S = 600.0
LINE: Tuple[LineDevice, ...] = (
    LineDevice('crusher', {'family': 'mcd', 'model': 'mcd500', 'address': 20}, 'mcd500',
               'mcd'),
    LineDevice('press', {'family': 'mcd', 'model': 'mcd3000', 'address': 21}, 'mcd3000',
               'mcd'),
    LineDevice('feeder', {'family': 'fc', 'model': 'fc51', 'address': 1,
                          'comms_timeout': SOAK_COMMS_TIMEOUT_S,
                          'comms_timeout_function': TIMEOUT_STOP}, 'fc51', 'drive'),
    LineDevice('fan', {'family': 'vlt', 'model': 'vlt5000', 'address': 2,
                       'comms_timeout': SOAK_COMMS_TIMEOUT_S, 'speed_reference': 25.0},
               'vlt5000', 'drive'),
    LineDevice('mixer', {'family': 'lvsg', 'model': 'mcd202', 'address': 5,
                         'gateway_input_register': 0,
                         'gateway_output_register': LVSG_OUTPUT_REGISTER}, 'lvsg', 'lvsg'),
    LineDevice('pump', {'family': 'fc', 'model': 'fc51', 'address': 3, 'allow_control': False,
                        'comms_timeout': SOAK_COMMS_TIMEOUT_S,
                        'comms_timeout_function': TIMEOUT_STOP},
               'fc51', 'drive'),
    LineDevice('silent_starter', {'family': 'mcd', 'model': 'mcd500', 'address': 30}, '',
               'mcd'),
)


@dataclass
class SoakSettings:
    """What to run: how long, how many faults and disturbances, how fast to give up."""

    transactions: int = 100_000
    fault_rate: float = 0.1
    seed: int = 1
    timeout_s: float = 0.1
    line: str = 'pty'  # 'pty' (real serial transport, real time) or 'virtual'
    command_period_s: float = 0.05  # a random command or speed reference this often
    poll_rate_hz: float = 100.0  # per device: more than the bus can carry, so it is busy
    burst_share: float = 0.2  # share of the steps that send 2-3 commands at once
    # Two commands in flight per device exercise a stop asked while a start still waits;
    # quick stops to the gateway, its Fwd Run right after a stop or reset (two bugs the
    # oracle found, fixed; test_soak.py keeps a scripted test of each).
    in_flight_per_device: int = 2  # commands waiting for their answer, per device
    lvsg_quick_stop: bool = True  # quick_stop to the gateway's MCD 202
    outage_period_s: float = 6.0  # a device goes silent this often (0: never)
    outage_s: Tuple[float, float] = (1.0, 2.5)
    trip_period_s: float = 8.0  # a device trips this often (0: never)
    invalid_reference_share: float = 0.1
    check_every: int = 0  # run the oracle every so many transactions and stop at a violation


@dataclass
class SoakReport:
    """What the soak saw; the zeros and the matches are the pass criteria."""

    transactions: int = 0
    elapsed_s: float = 0.0
    line_time_s: float = 0.0  # time on the line's clock (virtual or real)
    crashes: int = 0
    crash_texts: List[str] = field(default_factory=list)
    commands: Counter = field(default_factory=Counter)  # 'command outcome' -> count
    references: Counter = field(default_factory=Counter)  # 'accepted' / 'refused'
    outages: int = 0
    trips: int = 0
    offline_events: int = 0
    violations: List[Violation] = field(default_factory=list)
    injected: Counter = field(default_factory=Counter)  # fault kind -> count
    silenced: int = 0  # requests to a device during its outage (each a timeout)
    counted: Counter = field(default_factory=Counter)  # the same kinds, from bus statistics
    mismatches: List[str] = field(default_factory=list)  # per device, with its last error
    longest_gap_online_s: float = 0.0
    stopped_early: bool = False

    @property
    def violation_counts(self) -> Counter:
        """Return violation kind -> count."""
        return summarize(self.violations)

    def expected(self, counted_as: str) -> int:
        """Return the failures the statistics must show as ``counted_as`` (outages: timeouts)."""
        return sum(self.injected[kind] for kind in COUNTED_AS[counted_as]) + \
            (self.silenced if counted_as == 'timeout' else 0)

    @property
    def unexplained(self) -> int:
        """
        Return the faults counted neither as their kind nor as an ambiguous reply.

        A fault on the transaction right after one whose window got no valid answer may be
        counted as ``ambiguous`` instead of its kind: its frame could have been the answer
        the device still owed (docs/reliability.md, "owed replies").
        """
        missing = sum(self.expected(kind) - self.counted[kind] for kind in COUNTED_AS)
        return max(0, missing - self.counted['ambiguous'])

    @property
    def faults_match(self) -> bool:
        """Return whether every injected fault was counted, as its kind or as ambiguous."""
        return all(self.counted[kind] <= self.expected(kind) for kind in COUNTED_AS) and \
            self.unexplained == 0

    @property
    def passed(self) -> bool:
        """Return whether the soak meets its criteria."""
        return not (self.crashes or self.violations) and self.faults_match

    def lines(self, most: int = 20) -> List[str]:
        """Return the report as printable lines, at most ``most`` violations in full."""
        rate = self.transactions / self.elapsed_s if self.elapsed_s else 0.0
        lines = [
            f'transactions: {self.transactions} in {self.elapsed_s:.1f} s ({rate:.0f}/s), '
            f'{self.line_time_s:.1f} s of line time',
            f'crashes: {self.crashes}',
            'commands: ' + ', '.join(f'{key} {count}'
                                     for key, count in sorted(self.commands.items())),
            'speed references: ' + ', '.join(f'{key} {count}'
                                             for key, count in sorted(self.references.items())),
            f'outages {self.outages}, trips {self.trips}, offline events {self.offline_events}',
            f'violations: {len(self.violations)}']
        counts = self.violation_counts
        lines += [f'  {kind:24s} {counts[kind]:6d}  ({text})'
                  for kind, text in VIOLATION_KINDS.items() if counts[kind]]
        lines += [f'  - {violation.line()}' for violation in self.violations[:most]]
        lines.append(f'faults injected -> counted by the bus statistics (no_reply: plus '
                     f'{self.silenced} requests during outages):')
        for counted_as, kinds in COUNTED_AS.items():
            expected, counted = self.expected(counted_as), self.counted[counted_as]
            mark = 'ok' if counted == expected else \
                'MISMATCH' if counted > expected or self.unexplained else 'ambiguous'
            lines.append(f'  {"+".join(kinds):17s} {expected:6d} -> {counted_as:14s} '
                         f'{counted:6d}  {mark}')
        lines.append(f'  {"(any, see above)":17s} {"":6s} -> {"ambiguous":14s} '
                     f'{self.counted["ambiguous"]:6d}')
        lines += [f'  {text}' for text in self.mismatches]
        lines += [f'longest gap between requests to a device while online: '
                  f'{self.longest_gap_online_s * 1000:.0f} ms',
                  ('stopped at the first violation; ' if self.stopped_early else '')
                  + ('PASS' if self.passed else 'FAIL')]
        return lines


# -- the line ---------------------------------------------------------------------------
def _sim_device(device: LineDevice, now_s: float):
    if device.kind == 'lvsg':
        slave = LvsgSlave(McdModel(McdSimConfig(model='mcd202', **SIM_SETTINGS['mcd']), now_s),
                          0, LVSG_OUTPUT_REGISTER, extended=True)
        return LvsgGatewaySim([slave])
    return make_device(device.model, now_s, **SIM_SETTINGS[device.kind])


def make_line(fault_rate: float, seed: int, slow_s: float, timeout_s: float,
              clock: Optional[Callable[[], float]] = None,
              devices: Tuple[LineDevice, ...] = LINE) -> RecordingServer:
    """
    Return the simulated line (not started) with faults at ``fault_rate``.

    The faults of :data:`SOAK_FAULTS` are drawn: a 'late' reply comes 20 ms after the
    bridge's ``timeout_s``, in its quarantine.
    """
    now = (clock or time.monotonic)()
    served = {device.unit: (_sim_device(device, now), device.kind)
              for device in devices if device.model}
    server = RecordingServer(served, clock=clock)
    server.faults.set_plan(FaultPlan(fault_rate, SOAK_FAULTS, seed, slow_s=slow_s,
                                     master_timeout_s=timeout_s))
    return server


def line_config(port: str, timeout_s: float, poll_rate_hz: float,
                devices: Tuple[LineDevice, ...] = LINE) -> Tuple[Dict, Dict[str, Dict]]:
    """Return (bus settings, device settings) of the soak line, as in a params file."""
    values = {device.name: dict(device.values, poll_rate=poll_rate_hz if device.model
                                else 5.0)
              for device in devices}
    bus = {'protocol': 'modbus_rtu', 'port': port, 'baudrate': 19200, 'parity': 'N',
           'timeout': timeout_s, 'devices': list(values)}
    for name, gap in keepalive_gaps(build_config(bus, values)).items():
        values[name]['comms_timeout'] = gap.advised_s  # the rule's advice
    return bus, values


def make_soak_config(port: str, settings: SoakSettings) -> BridgeConfig:
    """Return the bridge configuration of the soak line, validated as the node does."""
    bus, values = line_config(port, settings.timeout_s, settings.poll_rate_hz)
    return build_config(bus, values)


def running_motors(server: RecordingServer, devices: Tuple[LineDevice, ...] = LINE) \
        -> Dict[str, str]:
    """Return device -> what still runs at the simulated device ('' when stopped)."""
    states = {}
    with server.lock:
        for device in devices:
            if not device.model:
                continue
            sim = server.devices[device.unit]
            if device.kind == 'mcd':
                running = sim.model.state in (STARTING, RUNNING)
                states[device.name] = f'starter state {sim.model.state}' if running else ''
            elif device.kind == 'drive':
                word = sim.model.control_word
                states[device.name] = f'control word 0x{word:04X} (run)' \
                    if fc_profile.is_start(word) and not sim.model.tripped else ''
            else:
                slave = sim.slaves[0]
                running = slave.control.fwd_run or slave.model.state in (STARTING, RUNNING)
                states[device.name] = f'gateway Fwd Run {slave.control.fwd_run}, starter ' \
                    f'state {slave.model.state}' if running else ''
    return states


class Disturbances:
    """Outages (a device goes silent, then answers again) and trips at the devices."""

    def __init__(self, server: RecordingServer, clock: Callable[[], float], rng: random.Random,
                 outage_period_s: float, outage_s: Tuple[float, float], trip_period_s: float,
                 devices: Tuple[LineDevice, ...] = LINE):
        self.server = server
        self.clock = clock
        self.random = rng
        self.outage_period_s = outage_period_s
        self.outage_s = outage_s
        self.trip_period_s = trip_period_s
        self.served = [device for device in devices if device.model]
        self.tripping = [device for device in self.served
                         if device.values.get('allow_control', True)]
        now = clock()
        self.next_outage_s = now + outage_period_s if outage_period_s > 0 else math.inf
        self.next_trip_s = now + trip_period_s if trip_period_s > 0 else math.inf
        self.silent: Dict[int, float] = {}  # unit -> when it answers again
        self.outages = 0
        self.trips = 0

    def step(self) -> None:
        """Start or end an outage, or trip a device, when due."""
        now = self.clock()
        for unit, until in list(self.silent.items()):
            if now >= until:
                self._power_on(unit)
        if now >= self.next_outage_s:
            self.next_outage_s = now + self.random.uniform(0.5, 1.5) * self.outage_period_s
            device = self.random.choice(self.served)
            if device.unit not in self.silent:
                self.silent[device.unit] = now + self.random.uniform(*self.outage_s)
                self.server.power_off(device.unit)
                self.outages += 1
        if now >= self.next_trip_s:
            self.next_trip_s = now + self.random.uniform(0.5, 1.5) * self.trip_period_s
            self._trip(self.random.choice(self.tripping), now)

    def _power_on(self, unit: int) -> None:
        del self.silent[unit]
        self.server.power_on(unit, self.server.devices[unit])  # the same device: a cut cable

    def _trip(self, device: LineDevice, now_s: float) -> None:
        with self.server.lock:
            sim = self.server.devices[device.unit]
            if device.kind == 'drive':
                sim.model.trip(ALARM_OVER_CURRENT, now_s)
            elif device.kind == 'mcd':
                sim.model.trip(self.random.choice(MCD_TRIPS), now_s)
            else:
                sim.slaves[0].model.trip(self.random.choice(MCD_TRIPS), now_s)
        self.trips += 1

    def end(self) -> None:
        """End every outage now."""
        for unit in list(self.silent):
            self._power_on(unit)


def commands_for(lvsg_quick_stop: bool) -> Dict[str, Tuple[str, ...]]:
    """Return the commands a driver picks from, per device kind."""
    commands = dict(COMMANDS)
    if not lvsg_quick_stop:
        commands['lvsg'] = tuple(command for command in COMMANDS['lvsg']
                                 if command != 'quick_stop')
    return commands


def random_reference(rng: random.Random, invalid_share: float) -> float:
    """Return a speed reference in percent: mostly valid, some invalid."""
    if rng.random() < invalid_share:
        return rng.choice(INVALID_REFERENCES)
    return round(rng.uniform(-100.0, 100.0), 2)


# -- the driver ---------------------------------------------------------------------------
class _Driver:
    """Sends random commands and speed references, as an integrator's program would."""

    def __init__(self, master: BusMaster, log: ClientLog, settings: SoakSettings,
                 clock: Callable[[], float]):
        self.master = master
        self.log = log
        self.settings = settings
        self.clock = clock
        self.random = random.Random(settings.seed + 1)
        self.next_s = clock()
        self.in_flight: Counter = Counter()
        self.references: Counter = Counter()
        self.commands = commands_for(settings.lvsg_quick_stop)
        self.offline: Dict[str, bool] = {}  # device -> reported offline (by the listener)

    def step(self) -> None:
        """Maybe send a command or a speed reference."""
        now = self.clock()
        if now < self.next_s:
            return
        self.next_s = now + self.settings.command_period_s
        count = self.random.choice((2, 3)) if self.random.random() < \
            self.settings.burst_share else 1
        for _ in range(count):
            self._act(self.random.choice(LINE))

    def _act(self, device: LineDevice) -> None:
        if self.offline.get(device.name) and self.random.random() < 0.8:
            return  # mostly, a caller leaves a device alone while it is reported offline
        if device.kind == 'drive' and self.random.random() < 0.3:
            self._reference(device)
            return
        if self.in_flight[device.name] >= self.settings.in_flight_per_device:
            return  # a caller waiting for its reply
        self.submit(device.name, self.random.choice(self.commands[device.kind]))

    def submit(self, name: str, command: str):
        """Submit a command, recorded with its answer; return the bus's future."""
        request = self.log.ask(name, command)
        self.in_flight[name] += 1
        future = self.master.submit_command(name, command)
        future.add_done_callback(functools.partial(self._answered, request))
        return future

    def _answered(self, request, future) -> None:
        self.log.answer_future(request, future)
        self.in_flight[request.device] -= 1

    def _reference(self, device: LineDevice) -> None:
        percent = random_reference(self.random, self.settings.invalid_reference_share)
        try:
            self.master.set_speed_reference(device.name, percent)
            accepted = True
        except CommandRefused:
            accepted = False
        self.log.reference(device.name, percent, accepted)
        self.references['accepted' if accepted else 'refused'] += 1


class _Listener:
    """The bus events the client is told of: offline, online, and a device that trips."""

    def __init__(self):
        self.log: Optional[ClientLog] = None
        self.tripped_told: Dict[str, bool] = {}
        self.offline: Dict[str, bool] = {}
        self.offline_events = 0
        self.handlers = handler_table({
            DeviceOffline: functools.partial(self._link_state, 'offline'),
            DeviceOnline: functools.partial(self._link_state, 'online'),
            ReadingEvent: self._reading, StateUnknown: ignore, Notice: ignore})

    def __call__(self, event: BusEvent) -> None:
        if self.log is not None:
            self.handlers[type(event)](event)

    def _link_state(self, state: str, event: BusEvent) -> None:
        self.log.notice(event.device, state)
        self.tripped_told[event.device] = False
        self.offline[event.device] = state == 'offline'
        self.offline_events += state == 'offline'

    def _reading(self, event: ReadingEvent) -> None:
        tripped = event.reading.tripped
        if tripped and not self.tripped_told.get(event.device):
            self.log.notice(event.device, 'tripped')
        self.tripped_told[event.device] = tripped


# -- the run ------------------------------------------------------------------------------
class SoakRun:
    """
    One soak run: the line, the bus, the driver and the disturbances.

    :func:`run_soak` runs it; a test may drive it by hand instead (:meth:`ask`,
    :meth:`run_for`, :meth:`shut_down`, :meth:`check`).
    """

    def __init__(self, settings: SoakSettings):
        self.settings = settings
        if settings.line not in ('pty', 'virtual'):
            raise ValueError(f'line must be pty or virtual, not {settings.line!r}')
        self.virtual = settings.line == 'virtual'
        self.clock = VirtualClock() if self.virtual else time.monotonic
        self.server = make_line(settings.fault_rate, settings.seed, 0.7 * settings.timeout_s,
                                settings.timeout_s, clock=self.clock if self.virtual else None)
        port = '/dev/null' if self.virtual else self.server.open_pty()
        config = make_soak_config(port, settings)
        self.listener = _Listener()
        if self.virtual:
            transport = VirtualLine(config.link, self.server, self.clock)
            self.master = BusMaster(transport, [d.make_spec() for d in config.devices],
                                    config.timing, listener=self.listener, clock=self.clock,
                                    sleep=self.clock.sleep)
        else:
            self.server.start()
            self.master = BusMaster(config.make_transport(),
                                    [d.make_spec() for d in config.devices], config.timing,
                                    listener=self.listener)
        self.log = ClientLog(lambda: self.server.seq, self.clock, exact=True)
        self.listener.log = self.log
        self.driver = _Driver(self.master, self.log, settings, self.clock)
        self.driver.offline = self.listener.offline
        self.disturbances = Disturbances(self.server, self.clock,
                                         random.Random(settings.seed + 2),
                                         settings.outage_period_s, settings.outage_s,
                                         settings.trip_period_s)
        self.report = SoakReport()

    def ask(self, name: str, command: str):
        """Submit ``command`` for device ``name`` now, recorded; return the future."""
        return self.driver.submit(name, command)

    def run_for(self, seconds: float, until: Optional[Callable[[], bool]] = None) -> None:
        """Run the bus (no random driver) for ``seconds`` of line time, or until ``until()``."""
        end = self.clock() + seconds
        while self.clock() < end and not (until is not None and until()):
            self.step()

    def check(self, final_states: Optional[Dict[str, str]] = None) -> List[Violation]:
        """Return the oracle's violations of the run so far."""
        return self.oracle().check(final_states)

    def sleep(self, seconds: float) -> None:
        """Let time pass on the line's clock."""
        if self.virtual:
            self.clock.sleep(seconds)
        else:
            time.sleep(seconds)

    def step(self) -> None:
        """Run one step of the bus and wait what it asks (5 ms at most); count a crash."""
        try:
            self.master.run_step(max_wait_s=0.005)
        except Exception as error:  # noqa: B902 - a crash is what the soak counts
            self.report.crashes += 1
            self.report.crash_texts.append(f'{type(error).__name__}: {error}')
            self.sleep(0.005)

    def loop(self, progress: Optional[Callable[[int], None]]) -> None:
        """Drive the bus at random until the settings' transactions are done."""
        settings = self.settings
        next_progress = 0
        next_check = settings.check_every or math.inf
        while True:
            done = self.master.transaction_count()
            if done >= settings.transactions:
                return
            if progress is not None and done >= next_progress:
                progress(done)
                next_progress += 10_000
            if done >= next_check:
                next_check += settings.check_every
                if self.oracle().check():
                    self.report.stopped_early = True
                    return
            self.disturbances.step()
            self.driver.step()
            self.step()

    def shut_down(self) -> Dict[str, str]:
        """End the disturbances and the faults, stop everything; return what still runs."""
        self.disturbances.end()
        plan = self.server.faults.plan
        self.server.faults.set_plan(replace(plan, rate=0.0))
        self.log.shutdown()
        future = self.master.begin_stop_all('soak end', timeout_s=5.0)
        deadline = self.clock() + 6.0
        while not future.done() and self.clock() < deadline:
            self.step()
        return running_motors(self.server)

    def oracle(self) -> Oracle:
        """Return the oracle over the run's records (a pty line: one request of slack)."""
        return Oracle(self.server.frames, self.log, [device.info for device in LINE],
                      slack=0 if self.virtual else 1)

    def close(self) -> None:
        """Close the bus and the line."""
        self.master.transport.close()
        if not self.virtual:
            self.server.stop()


def transport_class(line: str) -> type:
    """Return the class of the transport a soak on ``line`` runs on (to patch it)."""
    return VirtualLine if line == 'virtual' else RtuSerialTransport


def run_soak(settings: SoakSettings, progress: Optional[Callable[[int], None]] = None) \
        -> SoakReport:
    """Run the soak and return its report."""
    run = SoakRun(settings)
    report = run.report
    started = time.monotonic()
    line_started = run.clock()
    try:
        run.loop(progress)
        final_states = None if report.stopped_early else run.shut_down()
    finally:
        run.close()
    report.elapsed_s = time.monotonic() - started
    report.line_time_s = run.clock() - line_started
    report.violations = run.oracle().check(final_states)
    _fill_report(report, run)
    return report


def _fill_report(report: SoakReport, run: SoakRun) -> None:
    master, server = run.master, run.server
    report.transactions = master.transaction_count()
    report.crashes += master.internal_errors
    report.commands = run.log.outcomes()
    report.references = run.driver.references
    report.outages = run.disturbances.outages
    report.trips = run.disturbances.trips
    report.offline_events = run.listener.offline_events
    report.injected = server.faults.totals()
    silenced = Counter(frame.unit for frame in server.frames if frame.silenced)
    report.silenced = sum(silenced.values())
    for device in LINE:
        if not device.model:
            continue
        stats = master.snapshot(device.name).stats  # what /diagnostics shows
        report.counted['ambiguous'] += int(stats['errors_ambiguous'])
        for counted_as, kinds in COUNTED_AS.items():
            key = 'slow_replies' if counted_as == 'slow' else f'errors_{counted_as}'
            counted = int(stats[key])
            report.counted[counted_as] += counted
            injected = sum(server.faults.injected[(device.unit, kind)] for kind in kinds)
            if counted_as == 'timeout':
                injected += silenced[device.unit]
            if counted > injected:
                report.mismatches.append(f'{device.name}: {"+".join(kinds)} injected '
                                         f'{injected}, counted {counted} ({counted_as}); last '
                                         f'error: {stats["last_error"]}')
    report.longest_gap_online_s = longest_gap_online(server, run.log)


def longest_gap_online(server: RecordingServer, log: ClientLog,
                       devices: Tuple[LineDevice, ...] = LINE) -> float:
    """Return the longest time between two requests to a served device reported online."""
    longest = 0.0
    for device in devices:
        if not device.model:
            continue
        offline: List[List[float]] = []
        for notice in log.notices:
            if notice.device == device.name and notice.kind == 'offline':
                offline.append([notice.time_s, math.inf])
            elif notice.device == device.name and notice.kind == 'online' and offline:
                offline[-1][1] = notice.time_s
        times = [frame.time_s for frame in server.frames if frame.unit == device.unit]
        for before, after in zip(times, times[1:]):
            if not any(start < after and before < end for start, end in offline):
                longest = max(longest, after - before)
    return longest
