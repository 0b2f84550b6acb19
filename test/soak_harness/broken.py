"""
Deliberately broken bridges: the proof that the soak's oracle catches what it must.

Each variant is a context manager that patches one safety rule out of the bridge's classes
and puts it back on exit. A soak run inside it must report violations of the kinds listed
in :data:`EXPECTED_KINDS`; the unbroken bridge, same seed, must report none
(``test/integration/test_soak.py``, ``bench/soak.py --broken``). Never use them elsewhere.

- ``unanswered_keeps_start``: a start whose reply was lost leaves a cyclic device's image at
  run (the keepalive repeats a start the client was told failed).
- ``offline_keeps_command``: going offline forgets nothing (the old run word goes out on the
  probes and after the device is back).
- ``failed_start_resent``: a start whose reply was lost is queued again and sent later.
- ``monitor_only_writes``: the monitor-only guard is off (the runner's check, and the set-up
  writes that ask the same question, let writes through).
- ``transport_drops_writes``: the transport answers a share of the writes as acknowledged
  without sending them.
"""

from concurrent.futures import Future
import contextlib
import random
from typing import Dict, Iterator, Tuple, Type

from drive_bridge.bus.execution import CommandExecutor
from drive_bridge.bus.jobs import CommandJob
from drive_bridge.bus.motor import MotorOwner
from drive_bridge.bus.scheduler import BusScheduler
from drive_bridge.errors import TransportError
from drive_bridge.protocol.commands import Command

VARIANTS = ('unanswered_keeps_start', 'offline_keeps_command', 'failed_start_resent',
            'monitor_only_writes', 'transport_drops_writes')
# The violation kinds each variant must produce (at least one of them).
EXPECTED_KINDS: Dict[str, Tuple[str, ...]] = {
    'unanswered_keeps_start': ('run_after_failed_start',),
    'offline_keeps_command': ('run_after_end',),
    'failed_start_resent': ('run_after_failed_start',),
    'monitor_only_writes': ('monitor_only_write',),
    'transport_drops_writes': ('ack_not_on_wire',),
}
DROPPED_WRITE_SHARE = 0.2


@contextlib.contextmanager
def _patched(owner: type, name: str, replacement) -> Iterator[None]:
    own = name in owner.__dict__  # else inherited: the patch is removed again afterwards
    original = owner.__dict__.get(name)
    setattr(owner, name, replacement)
    try:
        yield
    finally:
        if own:
            setattr(owner, name, original)
        else:
            delattr(owner, name)


def _unanswered_keeps_start():
    original = MotorOwner.unanswered

    def unanswered(self, command, motion_before, now_s):
        original(self, command, motion_before, now_s)
        if command.may_start and self.cyclic:
            self._steady = Command.START  # broken: the lost start stays the keepalive's word
    return _patched(MotorOwner, 'unanswered', unanswered)


def _offline_keeps_command():
    return _patched(MotorOwner, 'on_offline', lambda self, now_s: None)


@contextlib.contextmanager
def _failed_start_resent():
    resend = []  # starts answered as failed, to be queued again on the bus thread
    run_command = CommandExecutor.run
    run_once = BusScheduler.run_once

    def run_command_keeping_failed_starts(self, job):
        run_command(self, job)
        error = job.future.exception() if job.future.done() else None
        if isinstance(error, TransportError) and job.command.may_start:
            resend.append(job)  # broken: queued again, behind the caller's back

    def run_once_resending(self):
        while resend:
            job = resend.pop()
            self.jobs.push(CommandJob(job.device, self.clock() +
                                      self.deadman.command_deadline_s, Future(), job.command))
        return run_once(self)

    with _patched(CommandExecutor, 'run', run_command_keeping_failed_starts), \
            _patched(BusScheduler, 'run_once', run_once_resending):
        yield


def _monitor_only_writes():
    return _patched(MotorOwner, 'writes_allowed', property(lambda self: True))


def _transport_drops_writes(transport_class: Type, seed: int):
    original = transport_class.execute
    rng = random.Random(seed)

    def execute(self, unit, request):
        if request.writes and rng.random() < DROPPED_WRITE_SHARE:
            return None  # broken: "acknowledged", never sent
        return original(self, unit, request)
    return _patched(transport_class, 'execute', execute)


def broken(variant: str, transport_class: Type, seed: int = 1):
    """Return the context manager that breaks the bridge as ``variant`` says."""
    if variant == 'transport_drops_writes':
        return _transport_drops_writes(transport_class, seed)
    makers = {'unanswered_keeps_start': _unanswered_keeps_start,
              'offline_keeps_command': _offline_keeps_command,
              'failed_start_resent': _failed_start_resent,
              'monitor_only_writes': _monitor_only_writes}
    if variant not in makers:
        raise ValueError(f'unknown variant {variant!r}: allowed {", ".join(VARIANTS)}')
    return makers[variant]()
