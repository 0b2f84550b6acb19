"""
Helpers of the safety tests: a babbling line, held replies, the motor read from the device.

Everything here reads the simulated devices (what they received and what their models do),
never the bridge: the tests judge the bridge by what reached the wire.
"""

from collections import deque
import subprocess
import sys
import threading
import time
from typing import Callable, Iterable, List, Optional

from drive_bridge.protocol.lvsg import Control
from drive_bridge.sim.mcd_model import RUNNING, STARTING, STOPPING

# FC control profile (manual 004 section 5.6.1; VLT option card manual 003): bit 6 is
# "start" (0 = ramp stop), bit 10 "data valid" (0 = the drive ignores the word).
CTW_START_BIT = 1 << 6
CTW_DATA_VALID_BIT = 1 << 10
# MCD Modbus Module register 40002 (manual section 8): 1 start, 2 stop, 3 reset,
# 4 quick stop (coast to stop), 5 forced communication trip.
MCD_START, MCD_STOP, MCD_RESET, MCD_QUICK_STOP = 1, 2, 3, 4
# Modbus function codes that write.
WRITE_FUNCTIONS = (0x05, 0x06, 0x0F, 0x10)


def is_run_word(word: int) -> bool:
    """Return whether an FC-profile control word asks the drive to run."""
    return bool(word & CTW_START_BIT and word & CTW_DATA_VALID_BIT)


def rising_edges(flags: Iterable[bool]) -> int:
    """Return how often ``flags`` goes from false (or the start) to true."""
    count, previous = 0, False
    for flag in flags:
        count += flag and not previous
        previous = flag
    return count


def wait_for(predicate: Callable[[], bool], timeout_s: float = 10.0,
             interval_s: float = 0.02) -> bool:
    """Poll ``predicate`` until it is true or ``timeout_s`` passed; return its last value."""
    deadline = time.monotonic() + timeout_s
    while True:
        value = predicate()
        if value or time.monotonic() > deadline:
            return bool(value)
        time.sleep(interval_s)


def sim_pty_master(server) -> int:
    """Return the pty master of a simulator: what is written there reaches the bridge."""
    return server.pty_master


def recorded(server) -> int:
    """Return how many requests the simulator recorded so far (``record_frames``)."""
    with server.lock:
        return len(server.stats.frames)


def write_frames(server, unit: int, since: int = 0) -> List[bytes]:
    """Return the write requests to ``unit`` recorded from request ``since`` on."""
    with server.lock:
        frames = list(server.stats.frames[since:])
    return [frame for frame in frames if frame[0] == unit and frame[1] in WRITE_FUNCTIONS]


def frames_to(server, unit: int) -> int:
    """Return how many requests to ``unit`` the simulator recorded (``record_frames``)."""
    with server.lock:
        return sum(1 for frame in server.stats.frames if frame[0] == unit)


class MotorProbe:
    """
    One simulated device's motor as the device knows it; subclasses per family.

    ``start_edges`` counts the starts the device received (a keepalive that repeats a run
    word counts once); ``run_writes`` counts every write that asks to run.
    """

    def __init__(self, server, unit: int):
        self.server = server
        self.unit = unit

    def start_edges(self) -> int:
        raise NotImplementedError

    def run_writes(self) -> int:
        raise NotImplementedError

    def last_write_stops(self) -> bool:
        """Return whether the last control write the device received is a stop."""
        raise NotImplementedError

    def moving(self) -> bool:
        """Return whether the motor turns now (the model advanced to now)."""
        raise NotImplementedError

    def stopped(self) -> bool:
        """Return whether the motor is at rest and nothing asks it to run."""
        return not self.moving() and self.last_write_stops()


class McdProbe(MotorProbe):
    """An MCD starter behind its Modbus Module (or AP ASCII)."""

    def __init__(self, server, unit: int, model=None):
        super().__init__(server, unit)
        self.model = model if model is not None else server.devices[unit].model

    def commands(self) -> List[int]:
        with self.server.lock:
            return list(self.model.commands_received)

    def start_edges(self) -> int:
        return self.commands().count(MCD_START)

    run_writes = start_edges

    def last_write_stops(self) -> bool:
        commands = [c for c in self.commands() if c != MCD_RESET]
        return not commands or commands[-1] in (MCD_STOP, MCD_QUICK_STOP)

    def moving(self) -> bool:
        with self.server.lock:
            self.model.advance(self.server.clock())
            return self.model.state in (STARTING, RUNNING, STOPPING)


class DriveProbe(MotorProbe):
    """An FC 51 or a VLT 5000/6000 (option card) drive."""

    def __init__(self, server, unit: int):
        super().__init__(server, unit)
        self.model = server.devices[unit].model

    def words(self) -> List[int]:
        with self.server.lock:
            return list(self.model.control_words_received)

    def forget(self) -> None:
        """
        Forget the words received so far: the counts below start from the next one.

        The simulator keeps the latest 1000 (50 s at 20 Hz), so counts taken a minute apart on
        a long-lived simulator compare two different windows; compare from here instead.
        """
        with self.server.lock:
            self.model.control_words_received.clear()

    def start_edges(self) -> int:
        return rising_edges(is_run_word(word) for word in self.words())

    def run_writes(self) -> int:
        return sum(1 for word in self.words() if is_run_word(word))

    def last_write_stops(self) -> bool:
        words = self.words()
        return not words or not is_run_word(words[-1])

    def moving(self) -> bool:
        with self.server.lock:
            self.model.advance(self.server.clock())
            return self.model.output_pct != 0.0


class LvsgProbe(MotorProbe):
    """An MCD 200 behind the simulated Profibus gateway (the gateway's first slave)."""

    def __init__(self, server, unit: int = 1, index: int = 0):
        super().__init__(server, unit)
        self.slave = server.devices[unit].slaves[index]
        self.model = self.slave.model

    def images(self) -> List[Control]:
        with self.server.lock:
            return [Control.decode(data) for data in self.slave.writes]

    def start_edges(self) -> int:
        with self.server.lock:
            return list(self.model.commands_received).count(MCD_START)

    def run_writes(self) -> int:
        return sum(1 for image in self.images() if image.fwd_run)

    def last_write_stops(self) -> bool:
        with self.server.lock:
            return not self.slave.control.fwd_run

    def moving(self) -> bool:
        with self.server.lock:
            self.slave.advance(self.server.clock())
            return self.model.state in (STARTING, RUNNING, STOPPING)


class ReplyHold:
    """
    A simulator reply hook that holds back, or drops, the reply to the start.

    The start is on the wire and executed, its acknowledgement not yet back. Armed by
    :meth:`arm`; ``seen`` is set when the start arrives. The reply is then held until
    :meth:`release` (at most ``max_hold_s``) and ``extra_s`` more, and sent, or dropped
    (``drop``): a lost reply.
    """

    def __init__(self, probe: MotorProbe, drop: bool = False, extra_s: float = 0.0,
                 wait_release: bool = True, max_hold_s: float = 10.0):
        self.probe = probe
        self.drop = drop
        self.extra_s = extra_s
        self.wait_release = wait_release
        self.max_hold_s = max_hold_s
        self.seen = threading.Event()
        self._release = threading.Event()
        self._baseline: Optional[int] = None
        self.seen_at_s = 0.0

    def arm(self) -> 'ReplyHold':
        self._baseline = self.probe.start_edges()
        self.seen.clear()
        self._release.clear()
        return self

    def release(self) -> None:
        self._release.set()

    def __call__(self, unit: int, data: bytes) -> Optional[bytes]:
        if self._baseline is None or unit != self.probe.unit or \
                self.probe.start_edges() <= self._baseline:
            return data
        self._baseline = None  # once
        self.seen_at_s = time.monotonic()
        self.seen.set()
        if self.wait_release:
            self._release.wait(self.max_hold_s)
        if self.extra_s:
            time.sleep(self.extra_s)  # the device answers late: a slow reply
        return None if self.drop else data


def spy_starts(model) -> deque:
    """
    Note when each start command reaches an MCD model (monotonic s): any simulator's.

    Wraps the model's ``write_register`` (the Modbus Module, AP ASCII and the LVSG gateway
    all go through it); returns the deque of times.
    """
    times: deque = deque()
    original = model.write_register

    def write_register(address: int, value: int, now_s: float) -> None:
        original(address, value, now_s)
        if address == 1 and value == MCD_START:
            times.append(time.monotonic())

    model.write_register = write_register
    return times


class HoldNext:
    """
    A simulator reply hook that holds back the next reply to ``unit``, whatever it answers.

    Until :meth:`release` (at most ``max_hold_s``): the bus thread waits in that transaction.
    """

    def __init__(self, unit: int, max_hold_s: float = 10.0):
        self.unit = unit
        self.max_hold_s = max_hold_s
        self.seen = threading.Event()
        self._release = threading.Event()
        self._armed = False

    def arm(self) -> 'HoldNext':
        self.seen.clear()
        self._release.clear()
        self._armed = True
        return self

    def release(self) -> None:
        self._release.set()

    def __call__(self, unit: int, data: bytes) -> Optional[bytes]:
        if self._armed and unit == self.unit:
            self._armed = False
            self.seen.set()
            self._release.wait(self.max_hold_s)
        return data


_BABBLER = """
import os, sys, time
fd, chunk, period = int(sys.argv[1]), bytes.fromhex(sys.argv[2]), float(sys.argv[3])
os.set_blocking(fd, False)
first = True
while True:
    try:
        os.write(fd, chunk)
    except BlockingIOError:
        pass
    if first:
        print('babbling', flush=True)
        first = False
    time.sleep(period)
"""


# What a babbling RS-485 line can carry at most: 115200 baud, 10 bits a character.
LINE_BYTES_PER_S = 11_520


class Babbler:
    """
    A device that keeps talking: child processes writing bytes to a pty master.

    Processes of their own (not threads), so the test process's GIL cannot pause them, and
    ``processes`` of them, so that a loaded machine seldom pauses them all at once. Together
    they write ``pattern`` at the byte rate of a 115200 baud line (a chunk every 1.4 ms on
    the line, each process every 2.8 ms: pauses far shorter than the 5 ms silence the
    bridge drains to): what a real line can do. A flood as fast as the processes could
    write (64 kB/s) starved the kernel's pty delivery for every pty on the machine, for
    seconds beside a CPU hog: other tests' simulators read nothing for 1.1 s (issue 27).
    """

    def __init__(self, fd: int, pattern: bytes = b'\xff' * 16, processes: int = 2):
        self.fd = fd
        self.pattern = pattern
        self.period_s = processes * len(pattern) / LINE_BYTES_PER_S
        self.count = processes
        self.processes: List[subprocess.Popen] = []

    def start(self) -> 'Babbler':
        for _ in range(self.count):
            process = subprocess.Popen(
                [sys.executable, '-S', '-c', _BABBLER, str(self.fd), self.pattern.hex(),
                 str(self.period_s)], pass_fds=[self.fd], stdout=subprocess.PIPE, text=True)
            self.processes.append(process)
            assert process.stdout.readline().strip() == 'babbling'
        return self

    def stop(self) -> None:
        processes, self.processes = self.processes, []
        for process in processes:
            process.kill()
            process.wait()
            process.stdout.close()

    def __enter__(self) -> 'Babbler':
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()


class CpuHog:
    """A child process that burns one core (``python3 -c 'while True: pass'``)."""

    def __init__(self):
        self.process: Optional[subprocess.Popen] = None

    def __enter__(self) -> 'CpuHog':
        self.process = subprocess.Popen([sys.executable, '-S', '-c', 'while True: pass'])
        return self

    def __exit__(self, *exc) -> None:
        self.process.kill()
        self.process.wait()


class FaultOnStart:
    """
    Spoil the reply to the next start a simulator receives by a fault of its own kinds.

    The simulators inject a fault into the next reply of a unit, whatever the request; a
    polled device's next reply is a poll's. This puts it on the start: an MCD's register
    40002 = 1 (Modbus, or B10's reply over AP ASCII), a drive's first run word (Modbus coils
    or registers, or an FC-protocol telegram). ``fired`` is set when it was injected.
    """

    def __init__(self, server, unit: int, kind: str, then_silent: bool = False):
        self.server = server
        self.unit = unit
        self.kind = kind
        self.then_silent = then_silent  # the device hears nothing after it executed the start
        self.fired = threading.Event()
        self._install()

    def _executed(self) -> None:
        """After the start was executed: switch the device's answers off if asked."""
        if self.then_silent:
            with self.server.lock:
                self.server.silent_units.add(self.unit)

    def _take(self) -> bool:
        """Return True once: the fault goes to this reply."""
        if self.fired.is_set():
            return False
        self.server.faults.injected[(self.unit, self.kind)] += 1
        self.fired.set()
        return True

    def _install(self) -> None:
        server = self.server
        if hasattr(server, '_message_fault'):  # AP ASCII: B10's reply
            answer = server._answer

            def ascii_answer(fragment):
                start = fragment.kind == 'message' and fragment.code == 'B10' and \
                    server._selected == self.unit and self._take()
                if start:
                    server._message_fault = self.kind
                reply = answer(fragment)
                if start:
                    self._executed()
                return reply
            server._answer = ascii_answer
        elif hasattr(server, '_serve_telegram'):  # the FC protocol: a run word
            serve = server._serve_telegram

            def serve_telegram(connection, telegram, raw):
                draw = server.faults.draw
                start = telegram.address.address == self.unit and \
                    is_run_word(telegram.pcd1) and self._take()
                if start:
                    server.faults.draw = lambda *args, **kwargs: self.kind
                try:
                    serve(connection, telegram, raw)
                finally:
                    server.faults.draw = draw
                if start:
                    self._executed()
            server._serve_telegram = serve_telegram
        else:  # Modbus: the MCD's start or a drive's run word
            draw_fault, answer = server._draw_fault, server._answer

            def modbus_draw(frame, usable):
                if frame.unit == self.unit and _modbus_start(frame.function, frame.data) and \
                        self._take():
                    return self.kind
                return draw_fault(frame, usable)

            def modbus_answer(frame, raw, fault=None):
                reply = answer(frame, raw, fault)
                if fault == self.kind and frame.unit == self.unit and \
                        _modbus_start(frame.function, frame.data):
                    self._executed()
                return reply
            server._draw_fault, server._answer = modbus_draw, modbus_answer


def _modbus_start(function: int, data: bytes) -> bool:
    """Return whether a Modbus request starts: MCD 40002 = 1, or an FC-profile run word."""
    if function == 0x06:
        address, value = int.from_bytes(data[0:2], 'big'), int.from_bytes(data[2:4], 'big')
        return (address == 1 and value == MCD_START) or \
            (address == 49999 and is_run_word(value))
    if function == 0x0F and int.from_bytes(data[0:2], 'big') == 0 and len(data) >= 7:
        return is_run_word(data[5] | data[6] << 8)  # coils 1-16, the low byte first
    if function == 0x10 and int.from_bytes(data[0:2], 'big') == 49999 and len(data) >= 7:
        return is_run_word(int.from_bytes(data[5:7], 'big'))
    return False
