"""
Soak test of one mixed RS-485 bus against the simulators, with seeded faults.

One simulated Modbus RTU line on a pty carries an MCD 500 and an MCD 3000 (soft starters),
an FC 51 and a VLT 5000 (drives), a Profibus gateway with an MCD 202 behind it, and one
configured address nobody answers. The simulator injects faults into a share of the
replies of the healthy devices (every kind in :mod:`drive_bridge.sim.faults`), while a
driver sends random commands and speed references through the bus master, exactly as the
ROS node does. Each device is wrapped in an audit that sees what it executes.

Figures (:class:`SoakReport`): crashes of the bus loop (must be 0); control writes nobody
asked for and starts sent more than once for one request (must be 0); faults injected
against failures counted by the bus statistics, by kind (must match); and the longest gap
between two requests a healthy device received, while it was online and overall.

No ROS: the bus master runs in this thread (``run_once``), the simulator on its own.
"""

from collections import Counter
from dataclasses import dataclass, field
import random
import struct
import threading
import time
from typing import Callable, Dict, List, Optional, Tuple

from drive_bridge.bus.master import BusEvent, BusMaster
from drive_bridge.config import build_config
from drive_bridge.devices import mcd
from drive_bridge.devices.drive import COIL_CONTROL
from drive_bridge.protocol import fc_control, lvsg, rtu
from drive_bridge.protocol.commands import Command
from drive_bridge.protocol.words import coils_to_words, registers_to_bytes
from drive_bridge.sim.devices import make_device
from drive_bridge.sim.faults import FaultPlan, MODBUS_FAULTS
from drive_bridge.sim.lvsg_gateway import LvsgGatewaySim, LvsgSlave
from drive_bridge.sim.mcd_model import McdModel, McdSimConfig
from drive_bridge.sim.modbus_server import ModbusSimServer

# Injected fault kind -> the bus statistics' failure kind it must be counted as.
COUNTED_AS = {'crc': 'crc', 'no_reply': 'timeout', 'slow': 'slow', 'exception': 'exception',
              'garbage': 'bad_frame', 'truncated': 'truncated',
              'wrong_address': 'wrong_address'}
DEAD_DEVICE = ('silent_starter', 30)
LVSG_OUTPUT_REGISTER = 100
COMMANDS = {
    'mcd': ('start', 'start', 'stop', 'stop', 'quick_stop', 'reset'),
    'fc': ('start', 'start', 'stop', 'stop', 'quick_stop', 'coast_stop', 'reset'),
    'lvsg': ('start', 'start', 'stop', 'stop', 'quick_stop', 'reset'),
}


@dataclass
class SoakSettings:
    """What to run: how many transactions, how many faults, how fast to give up."""

    transactions: int = 100_000
    fault_rate: float = 0.1
    seed: int = 1
    timeout_s: float = 0.1
    command_period_s: float = 0.05  # a random command or speed reference this often
    poll_rate_hz: float = 100.0  # per device: more than the bus can carry, so it is busy


@dataclass
class SoakReport:
    """What the soak saw; the zeros and the matches are the pass criteria."""

    transactions: int = 0
    elapsed_s: float = 0.0
    crashes: int = 0
    crash_texts: List[str] = field(default_factory=list)
    unasked_writes: int = 0
    unasked_texts: List[str] = field(default_factory=list)
    repeated_starts: int = 0
    commands: Counter = field(default_factory=Counter)  # outcome -> count
    injected: Counter = field(default_factory=Counter)  # fault kind -> count
    counted: Counter = field(default_factory=Counter)  # the same kinds, from bus statistics
    mismatches: List[str] = field(default_factory=list)  # per device, with its last error
    offline_events: int = 0
    longest_gap_online_s: float = 0.0
    longest_gap_s: float = 0.0

    @property
    def faults_match(self) -> bool:
        """Return whether every injected fault kind was counted exactly."""
        return all(self.counted[kind] == self.injected[kind] for kind in COUNTED_AS)

    @property
    def passed(self) -> bool:
        """Return whether the soak meets its criteria."""
        return not (self.crashes or self.unasked_writes or self.repeated_starts) and \
            self.faults_match

    def lines(self) -> List[str]:
        """Return the report as printable lines."""
        rate = self.transactions / self.elapsed_s if self.elapsed_s else 0.0
        lines = [
            f'transactions: {self.transactions} in {self.elapsed_s:.1f} s ({rate:.0f}/s)',
            f'crashes: {self.crashes}',
            f'control writes nobody asked for: {self.unasked_writes}',
            f'starts sent more than once for one request: {self.repeated_starts}',
            'commands: ' + ', '.join(f'{key} {count}'
                                     for key, count in sorted(self.commands.items())),
            'faults injected -> counted by the bus statistics:']
        for kind, counted_as in COUNTED_AS.items():
            mark = 'ok' if self.counted[kind] == self.injected[kind] else 'MISMATCH'
            lines.append(f'  {kind:14s} {self.injected[kind]:6d} -> {counted_as:14s} '
                         f'{self.counted[kind]:6d}  {mark}')
        lines += [f'  {text}' for text in self.mismatches]
        lines += [
            f'healthy devices marked offline (faults in a row): {self.offline_events}',
            f'longest gap between polls of a healthy device while online: '
            f'{self.longest_gap_online_s * 1000:.0f} ms',
            f'longest gap between polls of a healthy device overall: '
            f'{self.longest_gap_s * 1000:.0f} ms',
            'PASS' if self.passed else 'FAIL']
        return lines


# -- what the devices execute -----------------------------------------------------------
def _mcd_control(frame: rtu.RtuFrame) -> Optional[bool]:
    if frame.function == rtu.WRITE_SINGLE_REGISTER:
        address, value = rtu.parse_address_count(frame.data)
        if address == mcd.REGISTER['command'].address:
            return value == mcd.COMMAND_VALUES[Command.START]
    return None


def _drive_control(frame: rtu.RtuFrame) -> Optional[bool]:
    if frame.function == rtu.WRITE_MULTIPLE_COILS:
        address, count = rtu.parse_address_count(frame.data)
        if address == COIL_CONTROL and count >= 16:
            packed = frame.data[5:]
            coils = [bool(packed[i // 8] >> (i % 8) & 1) for i in range(16)]
            return fc_control.is_start(coils_to_words(coils)[0])
    return None


def _lvsg_control(frame: rtu.RtuFrame) -> Optional[bool]:
    if frame.function not in (rtu.WRITE_SINGLE_REGISTER, rtu.WRITE_MULTIPLE_REGISTERS):
        return None
    address = rtu.parse_address_count(frame.data)[0]
    if address != LVSG_OUTPUT_REGISTER:
        return None
    if frame.function == rtu.WRITE_SINGLE_REGISTER:
        registers = [rtu.parse_address_count(frame.data)[1]]
    else:
        payload = frame.data[5:]
        registers = list(struct.unpack(f'>{len(payload) // 2}H', payload))
    image = registers_to_bytes(registers, lvsg.EXTENDED_OUTPUT_BYTES, 'big')
    return lvsg.Control.decode(image).fwd_run


class CommandAudit:
    """Compare what each device executes with what the driver asked for."""

    def __init__(self, clock: Callable[[], float] = time.monotonic):
        self.clock = clock
        self.lock = threading.Lock()
        self.latest: Dict[int, str] = {}  # unit -> the latest command asked for
        self.pending_start: Dict[int, int] = {}  # unit -> run writes seen for it so far
        self.unasked: List[str] = []
        self.repeated_starts = 0
        self.running: Dict[int, bool] = {}  # level-controlled units: the last written command
        self.request_times: Dict[int, List[float]] = {}

    def asked(self, unit: int, command: str) -> None:
        """Record that ``command`` was asked for (call before submitting it)."""
        with self.lock:
            self.latest[unit] = command
            if command == 'start':
                self.pending_start[unit] = 0

    def answered(self, unit: int, command: str) -> None:
        """Record that the command's outcome is known."""
        with self.lock:
            if command == 'start':
                self.pending_start.pop(unit, None)

    def saw(self, unit: int, run: Optional[bool], level: bool) -> None:
        """
        Record one request a device received; ``run``: None, or a control write.

        ``level``: the device runs while the written command says run (drives' control
        word, the LVSG Fwd Run bit), so only a change from stop to run starts it; otherwise
        (MCD register 40002) each start write is a start.
        """
        now = self.clock()
        with self.lock:
            self.request_times.setdefault(unit, []).append(now)
            if run is None:
                return
            was_run = self.running.get(unit, False)
            if level:
                self.running[unit] = run
            starts = run and not (level and was_run)
            latest = self.latest.get(unit)
            if latest is None or (starts and latest != 'start'):
                self.unasked.append(f'address {unit}: {"run" if run else "stop"} written, '
                                    f'latest command asked: {latest}')
            if run and unit in self.pending_start:
                self.pending_start[unit] += 1
                if self.pending_start[unit] == 2:
                    self.repeated_starts += 1


class AuditedDevice:
    """A simulated device that tells the audit what it is about to execute."""

    def __init__(self, device, unit: int, classify: Callable[[rtu.RtuFrame], Optional[bool]],
                 audit: CommandAudit, level: bool):
        self.device = device
        self.unit = unit
        self.classify = classify
        self.audit = audit
        self.level = level

    def handle(self, frame: rtu.RtuFrame, now_s: float) -> Optional[rtu.RtuFrame]:
        """Record the request, then let the device answer it."""
        self.audit.saw(self.unit, self.classify(frame), self.level)
        return self.device.handle(frame, now_s)


# -- the bus ------------------------------------------------------------------------------
# name -> (configuration, simulated model, audit classifier, command family)
DEVICES: Dict[str, Tuple[dict, str, Callable, str]] = {
    'crusher': ({'family': 'mcd', 'model': 'mcd500', 'address': 20}, 'mcd500',
                _mcd_control, 'mcd'),
    'press': ({'family': 'mcd', 'model': 'mcd3000', 'address': 21}, 'mcd3000',
              _mcd_control, 'mcd'),
    'feeder': ({'family': 'fc', 'model': 'fc51', 'address': 1, 'comms_timeout': 1.0,
                'comms_timeout_function': 2}, 'fc51', _drive_control, 'fc'),
    'fan': ({'family': 'vlt', 'model': 'vlt5000', 'address': 2, 'comms_timeout': 1.0},
            'vlt5000', _drive_control, 'fc'),
    'mixer': ({'family': 'lvsg', 'model': 'mcd202', 'address': 5,
               'gateway_input_register': 0,
               'gateway_output_register': LVSG_OUTPUT_REGISTER}, 'lvsg', _lvsg_control,
              'lvsg'),
}


def _sim_device(model: str, now_s: float):
    if model == 'lvsg':
        slave = LvsgSlave(McdModel(McdSimConfig(model='mcd202'), now_s), 0,
                          LVSG_OUTPUT_REGISTER, extended=True)
        return LvsgGatewaySim([slave])
    return make_device(model, now_s)


def make_soak_bus(settings: SoakSettings, audit: CommandAudit) -> ModbusSimServer:
    """Return the simulated line (not started) with every healthy device audited."""
    now = time.monotonic()
    devices = {}
    for _, (values, model, classify, family) in DEVICES.items():
        unit = values['address']
        devices[unit] = AuditedDevice(_sim_device(model, now), unit, classify, audit,
                                      level=family != 'mcd')
    server = ModbusSimServer(devices)
    server.faults.set_plan(FaultPlan(settings.fault_rate, MODBUS_FAULTS, settings.seed,
                                     slow_s=0.7 * settings.timeout_s))
    return server


def make_soak_config(port: str, settings: SoakSettings):
    """Return the bridge configuration of the soak bus, validated as the node does."""
    device_values = {name: dict(values, poll_rate=settings.poll_rate_hz)
                     for name, (values, _, _, _) in DEVICES.items()}
    device_values[DEAD_DEVICE[0]] = {'family': 'mcd', 'model': 'mcd500',
                                     'address': DEAD_DEVICE[1], 'poll_rate': 5.0}
    bus = {'protocol': 'modbus_rtu', 'port': port, 'baudrate': 19200, 'parity': 'N',
           'timeout': settings.timeout_s, 'devices': list(device_values)}
    return build_config(bus, device_values)


# -- the run ------------------------------------------------------------------------------
class _Driver:
    """Sends random commands and speed references, as an integrator's program would."""

    def __init__(self, master: BusMaster, audit: CommandAudit, settings: SoakSettings):
        self.master = master
        self.audit = audit
        self.random = random.Random(settings.seed + 1)
        self.period_s = settings.command_period_s
        self.next_s = time.monotonic()
        self.waiting: List[tuple] = []
        self.outcomes: Counter = Counter()

    def step(self) -> None:
        """Maybe send something; collect the outcomes of earlier commands."""
        for entry in [entry for entry in self.waiting if entry[2].done()]:
            self.waiting.remove(entry)
            unit, command, future = entry
            self.audit.answered(unit, command)
            error = future.exception()
            self.outcomes[f'{command} {_outcome(error)}'] += 1
        now = time.monotonic()
        if now < self.next_s:
            return
        self.next_s = now + self.period_s
        name = self.random.choice(list(DEVICES))
        values, _, _, family = DEVICES[name]
        if family == 'fc' and self.random.random() < 0.3:
            self.master.set_speed_reference(name, self.random.uniform(-100.0, 100.0))
            self.outcomes['speed reference'] += 1
            return
        if any(entry[0] == values['address'] for entry in self.waiting):
            return  # one command at a time per device, as a caller waiting for its reply
        command = self.random.choice(COMMANDS[family])
        self.audit.asked(values['address'], command)
        self.waiting.append((values['address'], command,
                             self.master.submit_command(name, command)))

    def stop_all(self) -> None:
        """Record the shutdown's stops as asked for (stop_on_shutdown)."""
        for values, _, _, _ in DEVICES.values():
            self.audit.asked(values['address'], 'stop')


def _outcome(error: Optional[BaseException]) -> str:
    if error is None:
        return 'acknowledged'
    text = str(error)
    if 'nothing sent' in text:
        return 'refused before sending'
    if text.startswith('rejected by'):
        return 'rejected by the device'
    return 'unacknowledged'


class _OfflineLog:
    """Offline intervals of each device, from the bus events."""

    def __init__(self):
        self.intervals: Dict[str, List[List[float]]] = {}
        self.events = 0

    def __call__(self, event: BusEvent) -> None:
        now = time.monotonic()
        if event.kind == 'offline':
            self.events += event.device != DEAD_DEVICE[0]
            self.intervals.setdefault(event.device, []).append([now, float('inf')])
        elif event.kind == 'online' and self.intervals.get(event.device):
            self.intervals[event.device][-1][1] = now


def run_soak(settings: SoakSettings, progress: Optional[Callable[[int], None]] = None) \
        -> SoakReport:
    """Run the soak and return its report."""
    audit = CommandAudit()
    server = make_soak_bus(settings, audit)
    port = server.open_pty()
    server.start()
    offline = _OfflineLog()
    config = make_soak_config(port, settings)
    master = BusMaster(config.make_transport(), [device.make_spec() for device in config.devices],
                       config.timing, listener=offline)
    driver = _Driver(master, audit, settings)
    report = SoakReport()
    started = time.monotonic()
    try:
        _loop(master, driver, settings, report, progress)
        driver.stop_all()
        _shutdown_stops(master, report)
    finally:
        master.transport.close()
        server.stop()
    report.elapsed_s = time.monotonic() - started
    _fill_report(report, master, server, audit, offline, driver)
    return report


def _loop(master: BusMaster, driver: _Driver, settings: SoakSettings, report: SoakReport,
          progress: Optional[Callable[[int], None]]) -> None:
    next_progress = 0
    while True:
        done = master.transaction_count()
        if done >= settings.transactions:
            return
        if progress is not None and done >= next_progress:
            progress(done)
            next_progress += 10_000
        try:
            driver.step()
            wait_s = master.run_once()
        except Exception as error:  # noqa: B902 - a crash is what the soak counts
            report.crashes += 1
            report.crash_texts.append(f'{type(error).__name__}: {error}')
            wait_s = 0.01
        if wait_s > 0:
            time.sleep(min(wait_s, 0.005))


def _shutdown_stops(master: BusMaster, report: SoakReport) -> None:
    """Stop what the soak started, running the bus in this thread until the stops end."""
    future = master.begin_stop_all('soak end', timeout_s=5.0)
    deadline = time.monotonic() + 6.0
    while not future.done() and time.monotonic() < deadline:
        try:
            master.run_once()
        except Exception as error:  # noqa: B902 - counted
            report.crashes += 1
            report.crash_texts.append(f'{type(error).__name__}: {error}')


def _fill_report(report: SoakReport, master: BusMaster, server: ModbusSimServer,
                 audit: CommandAudit, offline: _OfflineLog, driver: _Driver) -> None:
    healthy = [name for name in master.device_names if name != DEAD_DEVICE[0]]
    report.transactions = master.transaction_count()
    report.crashes += master.internal_errors
    report.unasked_writes = len(audit.unasked)
    report.unasked_texts = audit.unasked[:10]
    report.repeated_starts = audit.repeated_starts
    report.commands = driver.outcomes
    report.injected = server.faults.totals()
    for name in healthy:
        stats = master.snapshot(name).stats  # what /diagnostics shows
        unit = DEVICES[name][0]['address']
        for kind, counted_as in COUNTED_AS.items():
            key = 'slow_replies' if counted_as == 'slow' else f'errors_{counted_as}'
            counted = int(stats[key])
            report.counted[kind] += counted
            injected = server.faults.injected[(unit, kind)]
            if counted != injected:
                report.mismatches.append(f'{name}: {kind} injected {injected}, counted '
                                         f'{counted} ({counted_as}); last error: '
                                         f'{stats["last_error"]}')
    report.offline_events = offline.events
    for name in healthy:
        unit = DEVICES[name][0]['address']
        times = audit.request_times.get(unit, [])
        intervals = offline.intervals.get(name, [])
        for before, after in zip(times, times[1:]):
            gap = after - before
            report.longest_gap_s = max(report.longest_gap_s, gap)
            if not any(start < after and before < end for start, end in intervals):
                report.longest_gap_online_s = max(report.longest_gap_online_s, gap)
