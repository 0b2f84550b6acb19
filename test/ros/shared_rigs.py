"""
Nodes shared by tests: one per rig, brought back to rest between tests.

A node's start costs about 0.6 s of CPU and 1-2 s of wall time until its devices are ready,
and its SIGTERM 0.7 s more. A test that sends the node no signal, asks it for no lifecycle
transition and waits for no exit needs no fresh process: it takes a node from here
(``with rigs.session('mcd', **bus) as session``, the fixture ``rigs`` of
test/ros/conftest.py), kept per rig (a family, or the mixed line) and bus settings. Before
a test takes a node again:

- the simulator is back to normal: no reply hook, no silent address, no random faults;
- every device is online and has control as configured (``allow_control`` back to true
  where the test switched it off), its motor stopped through the node (a stop is always
  sendable) and at rest in the simulator, and its state ``ready``;
- what the simulator recorded (requests, commands, control words, gateway images) is
  forgotten, so that a test counts from its own start, as with a fresh simulator;
- the test gets a new client (a fresh record of the topics; the latched state comes again).

A node that cannot be brought back so, or whose test failed, is ended (SIGTERM, its log
printed) and the next test gets a fresh one. Not shared: what a node counts over its life
(the counters in ``/diagnostics``) and what it remembers of commands (a reference
published, an automatic start's arming); a test that judges those starts a node of its own.

One node runs at a time: the nodes of a test process share its ROS domain, node name and
device names, so two would answer each other's clients. A test that takes another rig ends
the node before it, and a test that takes none (it starts a node of its own) ends every
shared node first (test/ros/conftest.py; a test takes a shared node through the fixture
named ``rigs``). The tests of one rig go to one pytest-xdist worker through the
``xdist_group`` mark of :func:`on_rig`, whatever their module (``rigs`` lives as long as
the worker's session), and run there one after another.
"""

from contextlib import contextmanager
from typing import Any, Callable, Dict, Iterator, Tuple
import weakref

from drive_bridge.sim.faults import FaultPlan
import pytest
from ros_helpers import RosClient
from safety_helpers import DriveProbe, LvsgProbe, McdProbe, MotorProbe, wait_for
from safety_ros import call_ok, make_mixed_rig, make_rig, READY_S, Session

# States of a device from which a stop brings it to 'ready' (not offline or unknown).
ANSWERING = ('ready', 'starting', 'running', 'stopping', 'restart_delay', 'tripped')


def probes_of(rig) -> Dict[str, MotorProbe]:
    """Return the motor probe of each device of a rig (a one-device Rig or a BusRig)."""
    return dict(rig.probes) if hasattr(rig, 'probes') else {rig.name: rig.probe}


def forget_history(rig) -> None:
    """Forget what the simulator recorded: the requests and every device's commands."""
    server = rig.server
    with server.lock:
        server.stats.frames.clear()
        for probe in probes_of(rig).values():
            if isinstance(probe, McdProbe):
                probe.model.commands_received.clear()
            elif isinstance(probe, DriveProbe):
                probe.model.control_words_received.clear()
            elif isinstance(probe, LvsgProbe):
                probe.model.commands_received.clear()
                probe.slave.writes.clear()


def normal_line(rig) -> None:
    """Take back what a test did to the simulator: hooks, silent addresses, faults."""
    server = rig.server
    with server.lock:
        server.reply_hook = None
        server.silent_units.clear()
    server.faults.set_plan(FaultPlan(rate=0.0, kinds=server.faults.plan.kinds))


def at_rest(session: Session) -> str:
    """
    Bring the node and its devices to rest with a new client; return '' or what failed.

    Each device: answering again, control as configured, stopped through the node, still in
    the simulator, ``ready``.
    """
    rig, client = session.rig, session.client
    for name, device in rig.devices.items():
        if not client.spin_until(lambda: client.state(name) in ANSWERING, READY_S):
            return f'{name} is {client.state(name)!r}, not answering'
        if device.get('allow_control', True) and \
                not client.set_parameter(f'{name}.allow_control', True).successful:
            return f'{name}: allow_control could not be set back to true'
        if client.state(name) == 'tripped':
            call_ok(client, name, 'reset')
        stop = call_ok(client, name, 'stop')
        if not stop.success:
            return f'{name}: stop refused: {stop.message}'
    for name, probe in probes_of(rig).items():
        if not wait_for(probe.stopped, 10.0):
            return f'{name}: the motor does not come to rest'
        if not client.wait_state(name, 'ready', 15.0):
            return f'{name} is {client.state(name)!r}, not ready'
    return ''


# Every SharedRigs of this process: a test that takes no shared node ends theirs first
# (end_shared_nodes, from test/ros/conftest.py).
_EVERY: 'weakref.WeakSet[SharedRigs]' = weakref.WeakSet()


def end_shared_nodes() -> None:
    """End every shared node of this process (before a test that starts a node of its own)."""
    for shared in list(_EVERY):
        shared.close()


def on_rig(rig: str, *values: Any) -> Any:
    """
    Return a test parameter (``values``) that runs on the shared node of ``rig``.

    Its ``xdist_group`` (``rig_<rig>``) gives every test of the rig to one worker, so that
    one node serves them; a test that is no parameter carries the mark itself.
    """
    return pytest.param(*values, marks=pytest.mark.xdist_group(f'rig_{rig}'))


class SharedRigs:
    """The shared nodes of a test process, one per rig and bus settings (fixture ``rigs``)."""

    def __init__(self, directory):
        self._directory = directory
        self._sessions: Dict[Tuple, Session] = {}
        _EVERY.add(self)

    @contextmanager
    def session(self, family: str, **bus: Any) -> Iterator[Session]:
        """Yield a node on a rig of ``family`` (:func:`make_rig`, default device settings)."""
        with self._take((family,), lambda: make_rig(family), bus) as session:
            yield session

    @contextmanager
    def mixed(self, **bus: Any) -> Iterator[Session]:
        """Yield a node on the four-device line of :func:`make_mixed_rig`."""
        with self._take(('mixed',), make_mixed_rig, bus) as session:
            yield session

    @contextmanager
    def _take(self, rig_key: Tuple, make: Callable[[], Any], bus: Dict[str, Any]):
        key = rig_key + tuple(sorted(bus.items()))
        session = self._sessions.pop(key, None)
        self.close()  # one node at a time: nodes of one domain would answer for each other
        if session is not None:
            problem = self._reuse(session)
            if problem:
                print(f'a fresh node: the shared one could not be brought to rest: {problem}')
                self._end(session)
                session = None
        if session is None:
            path = self._directory / f'{"_".join(map(str, rig_key))}_{len(self._sessions)}.yaml'
            session = Session(make(), path, **bus)
        try:
            yield session
        except BaseException:
            self._end(session)  # a failed test may leave anything behind: its log, then gone
            raise
        if session.process.poll() is None:
            self._sessions[key] = session
        else:
            self._end(session)

    def fresh(self, rig, path, **bus: Any) -> Session:
        """Return a node of its own on ``rig`` (a Session, for ``with``); shared ones end first."""
        self.close()
        return Session(rig, path, **bus)

    @staticmethod
    def _reuse(session: Session) -> str:
        if session.process.poll() is not None:
            return f'the node exited ({session.process.returncode})'
        normal_line(session.rig)
        session.close_client()
        session.client = RosClient(list(session.rig.devices), drives=list(session.rig.drives))
        session.closed = False
        problem = at_rest(session)
        forget_history(session.rig)
        return problem

    @staticmethod
    def _end(session: Session) -> None:
        session.__exit__(None, None, None)

    def close(self) -> None:
        """End every node (SIGTERM, log printed) and stop its simulator."""
        sessions, self._sessions = list(self._sessions.values()), {}
        for session in sessions:
            self._end(session)
