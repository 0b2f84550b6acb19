"""
The soak's simulated line: the Modbus simulator with a log of what each device received.

:class:`RecordingServer` is the simulator (``sim.modbus_server.ModbusSimServer``) with a
line log: every request frame the line carried, numbered in order (the *line sequence*, 1,
2, ...), with its time, the fault injected into its reply, whether the device executed it,
and what a control write meant to the device (:class:`WireFrame`). The meaning comes from the
device side only: the frame's bytes read with the manuals' register maps, and for the gateway
the output image it holds before and after the write. Nothing of the bridge is read.

The line is served on a pty (the bridge's own serial transport, real time, the simulator on
its thread) or through :class:`VirtualLine`: the same transport and line discipline on a
byte line that hands each request to the simulator in the caller's thread and moves a
:class:`VirtualClock` by the wire time, a timeout for a lost reply. A virtual run does not
depend on the machine's load: the same seed gives the same run.
"""

from dataclasses import dataclass, replace
from typing import Callable, Dict, List, Optional, Tuple

from drive_bridge.protocol import fc_profile as ctw, rtu
from drive_bridge.protocol.lvsg import Control
from drive_bridge.protocol.rtu import RtuFrame
from drive_bridge.sim.faults import mangle_rtu_reply, MODBUS_FAULTS
from drive_bridge.sim.modbus_server import ModbusSimServer
from drive_bridge.transport.link import LinkSettings
from drive_bridge.transport.serial_rtu import RtuSerialTransport

WRITE_FUNCTIONS = (rtu.WRITE_SINGLE_COIL, rtu.WRITE_SINGLE_REGISTER, rtu.WRITE_MULTIPLE_COILS,
                   rtu.WRITE_MULTIPLE_REGISTERS)
# MCD Modbus Module, manual 000 section 6: register 40002 (frame address 1) and its values.
MCD_COMMAND_ADDRESS = 1
MCD_COMMAND_NAMES = {1: 'start', 2: 'stop', 3: 'reset', 4: 'quick_stop', 5: 'forced_comms_trip'}
# FC profile over Modbus (manual 004 section 5.2.8): coils 1-16 control word, 17-32 reference;
# register 50000 (CTW), frame address 49999.
DRIVE_CTW_REGISTER = 49999
KINDS = ('mcd', 'drive', 'lvsg')
TURNAROUND_S = 0.001  # a virtual device's time to answer


@dataclass(frozen=True)
class ControlWrite:
    """
    What one control write meant to the device that executed it.

    ``label``: 'start' (the device may run because of it: an MCD start, a drive run word, a
    Fwd Run image that sets or holds Fwd Run without Quick Stop, or sets it with), 'stop',
    'quick_stop', 'coast_stop', 'reset', 'forced_comms_trip', 'quick_stop_hold' (the gateway's
    Quick Stop set while Fwd Run is held: the first half of a quick stop), 'ignored' (a drive
    word without "data valid"). ``word`` and ``reference``: a drive's control and reference
    words (``reference`` None when the write does not carry one).
    """

    label: str
    text: str
    word: Optional[int] = None
    reference: Optional[int] = None

    @property
    def run(self) -> bool:
        """Return whether the write may make the motor run."""
        return self.label == 'start'


@dataclass(frozen=True)
class WireFrame:
    """One request the line carried; ``seq`` is its place on the line (1, 2, ...)."""

    seq: int
    time_s: float
    unit: int
    function: int
    data: bytes
    fault: Optional[str]  # the fault injected into the reply (None: a clean reply)
    executed: bool  # the device acted on it (served, answered without an exception)
    control: Optional[ControlWrite] = None
    silenced: bool = False  # a served device that was silent then (an outage)
    late: bool = False  # taken from a backlog: it was on the wire earlier than its place

    @property
    def writes(self) -> bool:
        """Return whether the request is a write (any function that may change the device)."""
        return self.function in WRITE_FUNCTIONS

    @property
    def acknowledged(self) -> bool:
        """Return whether the device's reply reached the master intact (maybe late)."""
        return self.executed and self.fault in (None, 'slow')


def drive_label(word: int) -> str:
    """Return what an FC-profile control word asks (manual 004 section 5.6.1)."""
    if not word & (1 << ctw.CTW_DATA_VALID):
        return 'ignored'
    if ctw.is_start(word):
        return 'start'
    if word & (1 << ctw.CTW_RESET):
        return 'reset'
    if not word & (1 << ctw.CTW_COAST_OFF):
        return 'coast_stop'
    if not word & (1 << ctw.CTW_QUICK_STOP_OFF):
        return 'quick_stop'
    return 'stop'


def lvsg_label(before: Control, after: Control) -> str:
    """Return what a new gateway output image asks, given the image it replaces."""
    if after.fwd_run and (not before.fwd_run or not after.quick_stop):
        return 'start'  # a rising Fwd Run starts; a held one without Quick Stop keeps running
    if after.reset:
        return 'reset'
    if after.fwd_run:
        return 'quick_stop_hold'
    return 'quick_stop' if after.quick_stop else 'stop'


def _image_text(image: Control) -> str:
    bits = [name for name, on in (('Fwd Run', image.fwd_run), ('Reset', image.reset),
                                  ('Quick Stop', image.quick_stop)) if on]
    return f'image [{", ".join(bits) or "no control bits"}]'


class _DeviceFace:
    """How to read one simulated device's control writes (see :func:`face_for`)."""

    kind = ''

    def __init__(self, device):
        self.device = device

    def before(self, frame: RtuFrame):
        """Return what the write may change, read before it is executed."""
        return None

    def control(self, frame: RtuFrame, before) -> Optional[ControlWrite]:
        """Return what an executed write meant, or None if it is no control write."""
        return None


class _McdFace(_DeviceFace):
    kind = 'mcd'

    def control(self, frame: RtuFrame, before) -> Optional[ControlWrite]:
        if frame.function != rtu.WRITE_SINGLE_REGISTER:
            return None
        address, value = rtu.parse_address_count(frame.data)
        if address != MCD_COMMAND_ADDRESS:
            return None
        label = MCD_COMMAND_NAMES.get(value, 'unknown')
        return ControlWrite(label, f'40002 = {value} ({label})')


class _DriveFace(_DeviceFace):
    kind = 'drive'

    def control(self, frame: RtuFrame, before) -> Optional[ControlWrite]:
        words = _drive_words(frame)
        if words is None:
            return None
        word, reference = words
        label = drive_label(word)
        text = f'control word 0x{word:04X} ({label})' + \
            ('' if reference is None else f', reference 0x{reference:04X}')
        return ControlWrite(label, text, word, reference)


def _drive_words(frame: RtuFrame) -> Optional[Tuple[int, Optional[int]]]:
    """Return (control word, reference or None) of a process-data write, else None."""
    if frame.function == rtu.WRITE_MULTIPLE_COILS:
        address, count = rtu.parse_address_count(frame.data)
        if address != 0 or count < 16:
            return None
        packed = frame.data[5:]
        coils = [bool(packed[i // 8] >> (i % 8) & 1) for i in range(min(count, 32))]
        words = [sum(1 << bit for bit in range(16) if coils[16 * n + bit])
                 for n in range(len(coils) // 16)]
        return words[0], (words[1] if len(words) > 1 else None)
    if frame.function == rtu.WRITE_SINGLE_REGISTER:
        address, value = rtu.parse_address_count(frame.data)
        if address == DRIVE_CTW_REGISTER:
            return value, None
    return None


class _LvsgFace(_DeviceFace):
    kind = 'lvsg'

    def __init__(self, device):
        super().__init__(device)
        self.slave = device.slaves[0]

    def before(self, frame: RtuFrame) -> Control:
        return replace(self.slave.control)

    def control(self, frame: RtuFrame, before: Control) -> Optional[ControlWrite]:
        if frame.function not in (rtu.WRITE_SINGLE_REGISTER, rtu.WRITE_MULTIPLE_REGISTERS):
            return None
        address, count = rtu.parse_address_count(frame.data)
        if frame.function == rtu.WRITE_SINGLE_REGISTER:
            count = 1
        if not address <= self.slave.output_register < address + count:
            return None  # the parameter request alone: the control bits are not written
        after = self.slave.control
        return ControlWrite(lvsg_label(before, after), _image_text(after))


def face_for(kind: str, device) -> _DeviceFace:
    """Return the reader of control writes for a simulated device of ``kind``."""
    faces = {'mcd': _McdFace, 'drive': _DriveFace, 'lvsg': _LvsgFace}
    if kind not in faces:
        raise ValueError(f'unknown device kind {kind!r}: allowed {", ".join(KINDS)}')
    return faces[kind](device)


class RecordingServer(ModbusSimServer):
    """
    The simulator with a line log; see the module docstring.

    ``devices``: address -> (simulated device, kind). The log (``frames``) grows by one
    :class:`WireFrame` per request, in line order; ``seq`` is the number of requests so far.
    """

    def __init__(self, devices: Dict[int, Tuple[object, str]],
                 clock: Callable[[], float] = None):
        kwargs = {} if clock is None else {'clock': clock}
        super().__init__({unit: device for unit, (device, _) in devices.items()}, **kwargs)
        self.faces = {unit: face_for(kind, device) for unit, (device, kind) in devices.items()}
        self.frames: List[WireFrame] = []

    @property
    def seq(self) -> int:
        """Return the number of requests the line carried so far."""
        return len(self.frames)

    def take_bytes(self, connection, gap_elapsed: bool) -> None:
        """
        Take what one read brought; mark a backlog.

        A master sends its next request only after the reply to the last one, or after
        giving up on it: several requests in one read mean this thread was held up (a
        loaded machine) and took them late, so their place on the line is uncertain.
        """
        first = len(self.frames)
        super().take_bytes(connection, gap_elapsed)
        if len(self.frames) - first > 1:
            with self.lock:
                self.frames[first:] = [replace(frame, late=True)
                                       for frame in self.frames[first:]]

    def _answer(self, frame: RtuFrame, raw: bytes,
                fault: Optional[str] = None) -> Optional[RtuFrame]:
        """Answer as the simulator does, and log the request with what it meant."""
        with self.lock:
            face = self.faces.get(frame.unit)
            silenced = face is not None and frame.unit in self.silent_units
            served = face is not None and not silenced
            before = face.before(frame) if served else None
            reply = super()._answer(frame, raw, fault)
            executed = served and reply is not None and not reply.function & 0x80
            control = face.control(frame, before) if executed else None
            if control is not None and control.label == 'ignored':
                executed = False
            self.frames.append(WireFrame(len(self.frames) + 1, self.clock(), frame.unit,
                                         frame.function, bytes(frame.data), fault, executed,
                                         control, silenced))
        return reply

    def exchange(self, frame: RtuFrame, raw: bytes) -> Tuple[Optional[bytes], Optional[str]]:
        """
        Carry one request as the serving thread would (virtual line); return the reply.

        Returns (the reply's bytes as sent, possibly spoiled by a fault, or None for
        silence; the fault injected, whose timing the virtual line keeps).
        """
        fault = self._draw_fault(frame, MODBUS_FAULTS)
        reply = self._answer(frame, raw, fault)
        if reply is None:
            return None, fault
        data = reply.encode()
        if fault is not None:
            data = mangle_rtu_reply(fault, data, self.faults)
        return data or None, fault


class VirtualClock:
    """Time that moves only when the line or the loop moves it."""

    def __init__(self, start_s: float = 1000.0):
        self.now = start_s

    def __call__(self) -> float:
        """Return the time now."""
        return self.now

    def sleep(self, seconds: float) -> None:
        """Let ``seconds`` pass."""
        self.now += max(0.0, seconds)


class VirtualByteLine:
    """
    A byte line onto a :class:`RecordingServer` in the caller's thread, on a virtual clock.

    Each request written is framed and handed to the simulator at once; its reply arrives
    byte by byte at the wire's pace after the request's wire time and a turnaround, a 'slow'
    one ``slow_s`` later, a 'late' one after the master's timeout, a 'late_batched' one with
    the next request's. Reads move the clock to the byte they wait for, or to their timeout.
    """

    def __init__(self, server: RecordingServer, clock: VirtualClock, char_s: float):
        self.server = server
        self.clock = clock
        self.char_s = char_s
        self.arrivals: List[Tuple[float, int]] = []  # (time, byte) not yet read
        self.held = b''  # late_batched replies, sent with the next request's
        self.is_open = False

    def connect(self) -> None:
        """Open the (virtual) line."""
        self.is_open = True

    def close(self) -> None:
        """Close the line."""
        self.is_open = False

    def write(self, data: bytes, deadline: float) -> None:
        """Hand the request to the simulator; schedule what it sends back."""
        request_s = len(data) * self.char_s
        if self.held:
            self._arrive(request_s, self.held)
            self.held = b''
        frame = rtu.decode_request(data).frame
        if frame is None:
            return
        reply, fault = self.server.exchange(frame, data)
        if reply is None:
            return
        if fault == 'late_batched':
            self.held += reply
            return
        self._arrive(request_s + TURNAROUND_S + self._delay_s(fault), reply)

    def _delay_s(self, fault: Optional[str]) -> float:
        plan = self.server.faults.plan
        if fault == 'slow':
            return plan.slow_s
        if fault == 'late':
            return plan.master_timeout_s + plan.late_s
        return 0.0

    def _arrive(self, delay_s: float, data: bytes) -> None:
        start = self.clock() + delay_s
        self.arrivals.extend((start + (i + 1) * self.char_s, byte) for i, byte in enumerate(data))
        self.arrivals.sort(key=lambda arrival: arrival[0])

    def _take(self, count: int) -> bytes:
        now = self.clock()
        taken = [byte for moment, byte in self.arrivals[:count] if moment <= now]
        del self.arrivals[:len(taken)]
        return bytes(taken)

    def read(self, count: int, timeout_s: float, at_least: int = 1) -> bytes:
        """Return up to ``count`` bytes, moving the clock to ``at_least`` or the timeout."""
        wanted = min(at_least, count)
        there = sum(1 for moment, _ in self.arrivals if moment <= self.clock())
        if there < wanted and timeout_s > 0:
            end = self.clock() + timeout_s
            due = self.arrivals[wanted - 1][0] if len(self.arrivals) >= wanted else end
            self.clock.sleep(min(due, end) - self.clock())
        return self._take(count)

    def wait_quiet(self, timeout_s: float) -> bytes:
        """Let ``timeout_s`` pass; return what arrived."""
        self.clock.sleep(timeout_s)
        return self._take(len(self.arrivals))


class VirtualLine(RtuSerialTransport):
    """
    The bridge's own RTU transport, line discipline included, on a :class:`VirtualByteLine`.

    Every fault is told apart as on a serial port: silence is a timeout, a short reply is
    truncated after the timeout, a bad CRC, a wrong address and garbage are bad frames, a
    'slow' reply arrives late but valid, a late one is discarded in the quarantine.
    """

    def __init__(self, settings: LinkSettings, server: RecordingServer, clock: VirtualClock):
        timing_line = LinkSettings(**{**settings.__dict__, 'port': '/dev/virtual'})
        char_s = rtu.character_time_s(settings.baudrate, settings.effective_parity,
                                      settings.effective_stopbits)
        super().__init__(timing_line, paced=False, clock=clock,
                         line=VirtualByteLine(server, clock, char_s))
        self.server = server
