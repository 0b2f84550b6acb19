"""
Late replies through the node, one case per wire: the motor read from the simulated device.

Issue 40 found, on every serial wire, a start whose reply came late and then a stop the
device never executed answered ``success`` while the motor ran: the stop's window took the
start's late acknowledgement. Here the start's reply comes 20 ms after the node's timeout
(``late``), or with the next request (``late_batched``), and the device hears nothing once it
executed the start; a stop called meanwhile goes next. It must be answered as failed, the
motor runs on (read from the simulator), nothing starts it again, and the node's end stops it
once the device answers again. A bridge that takes the late acknowledgement for the stop's
fails here (checked with the line discipline's quarantine and suspects taken out).
"""

import signal

from drive_bridge.sim.ap_ascii_server import make_ap_ascii_server
from drive_bridge.sim.devices import make_sim_server
from drive_bridge.sim.fc_protocol_server import make_fc_protocol_server
import pytest
from safety_helpers import DriveProbe, FaultOnStart, MCD_START, MCD_STOP, McdProbe, wait_for
from safety_ros import (
    call_later, clean_exit, Lifecycle, READY_S, Rig, Session, status_values)

TIMEOUT_S = 0.3
MCD = {'family': 'mcd', 'model': 'mcd500', 'address': 20, 'poll_rate': 5.0}
FC51 = {'family': 'fc', 'model': 'fc51', 'address': 1, 'poll_rate': 5.0,
        'speed_reference': 50.0}
SHORT_RAMPS = {'mcd': {'start_time_s': 2.0, 'stop_time_s': 0.3},
               'fc': {'ramp_up_s': 2.0, 'ramp_down_s': 0.3}}


class TcpRig(Rig):
    """A rig whose simulator listens on TCP (RTU frames over TCP, a transparent gateway)."""

    def bus_settings(self, **extra):
        return {'protocol': 'rtu_over_tcp', 'tcp_port': self.server.tcp_port,
                'timeout': TIMEOUT_S, 'diagnostics_period': 0.2, 'backoff_max': 1.0, **extra}


def mcd_rtu() -> Rig:
    server = make_sim_server({20: 'mcd500'}, settings={'mcd': SHORT_RAMPS['mcd']})
    server.open_pty()
    server.start()
    return Rig('mcd', server, McdProbe(server, 20), dict(MCD), bus={'timeout': TIMEOUT_S})


def fc51_rtu() -> Rig:
    server = make_sim_server({1: 'fc51'}, settings={'fc': SHORT_RAMPS['fc']})
    server.open_pty()
    server.start()
    return Rig('fc', server, DriveProbe(server, 1), dict(FC51), bus={'timeout': TIMEOUT_S})


def mcd_ap_ascii() -> Rig:
    server = make_ap_ascii_server({20: 'mcd500'}, **SHORT_RAMPS['mcd'])
    server.open_pty()
    server.start()
    return Rig('mcd', server, McdProbe(server, 20, model=server.devices[20]), dict(MCD),
               bus={'protocol': 'ap_ascii', 'timeout': TIMEOUT_S})


def fc51_fc_protocol() -> Rig:
    server = make_fc_protocol_server({1: 'fc51'}, settings=SHORT_RAMPS['fc'])
    server.open_pty()
    server.start()
    return Rig('fc', server, DriveProbe(server, 1), dict(FC51),
               bus={'protocol': 'fc_protocol', 'timeout': TIMEOUT_S})


def mcd_rtu_over_tcp() -> Rig:
    server = make_sim_server({20: 'mcd500'}, settings={'mcd': SHORT_RAMPS['mcd']})
    server.open_tcp(framing='rtu')
    server.start()
    return TcpRig('mcd', server, McdProbe(server, 20), dict(MCD))


WIRES = {'mcd_modbus_rtu': mcd_rtu, 'fc51_modbus_rtu': fc51_rtu, 'mcd_ap_ascii': mcd_ap_ascii,
         'fc51_fc_protocol': fc51_fc_protocol, 'mcd_rtu_over_tcp': mcd_rtu_over_tcp}


def set_plan_timing(server) -> None:
    """Make the simulator's late replies come 20 ms after the node's timeout."""
    from dataclasses import replace
    server.faults.set_plan(replace(server.faults.plan, master_timeout_s=TIMEOUT_S,
                                   late_s=0.02))


def power(server, unit: int, on: bool) -> None:
    """Switch the simulated device's answers on or off (a device that hears nothing)."""
    with server.lock:
        (server.silent_units.discard if on else server.silent_units.add)(unit)


@pytest.mark.parametrize('kind', ['late', 'late_batched'])
@pytest.mark.parametrize('wire', list(WIRES))
def test_a_start_answered_late_is_unanswered_and_a_stop_is_done_only_by_its_own_answer(
        wire, kind, tmp_path):
    """
    The start's reply comes late (or held); the device hears nothing after the start.

    The stop, called while the start waits for its reply, goes next: its own reply cannot
    come, and the start's (the same shape for a drive) must not be taken for it.
    """
    rig = WIRES[wire]()
    set_plan_timing(rig.server)
    unit = rig.device['address']
    with Session(rig, tmp_path / 'late.yaml') as session:
        client = session.client
        assert client.wait_state(rig.name, 'ready', READY_S)
        starts = FaultOnStart(rig.server, unit, kind, then_silent=True)
        start = call_later(client, rig.name, 'start')
        assert client.spin_until(starts.fired.is_set, 10.0)
        stop = call_later(client, rig.name, 'stop')  # behind the start's transaction
        assert client.spin_until(lambda: start.done() and stop.done(), 20.0)
        started, stopped = start.result(), stop.result()
        assert not started.success, started.message  # its answer never came in time
        assert 'may or may not have been executed' in started.message, started.message
        assert not stopped.success, \
            f'a stop the device never got was answered: {stopped.message}'
        assert wait_for(rig.probe.moving, 5.0), 'the device did not execute the start'
        if rig.family == 'mcd':  # the stop did not reach it: the starter runs on
            assert not rig.probe.last_write_stops()
        assert client.spin_until(
            lambda: 'may be running' in status_values(client.diagnostics(rig.name))
            .get('motor', ''), 10.0), client.diagnostics(rig.name)
        power(rig.server, unit, True)
        assert client.spin_until(lambda: client.state(rig.name) != 'offline', 20.0)
        assert rig.probe.start_edges() == 1  # never started again
        code, output = session.signal(signal.SIGTERM)
    assert clean_exit(code, output), output
    assert wait_for(rig.probe.stopped, 10.0), 'the node ended with the motor running'
    assert rig.probe.start_edges() == 1


def test_a_late_ready_reading_never_settles_a_start_answered_late_and_deactivate_stops(
        tmp_path):
    """
    A late 'ready' and a late start acknowledgement are never taken; deactivate stops it.

    The poll before the start answers late ('ready', taken before the start ran), then the
    start's reply comes late: neither is taken, nothing stale is published, the motor counts
    as possibly running until deactivate stops it (read from the simulator).
    """
    rig = mcd_rtu()
    set_plan_timing(rig.server)
    with Session(rig, tmp_path / 'late_ready.yaml') as session:
        client = session.client
        assert client.wait_state(rig.name, 'ready', READY_S)
        published_before = len(client.values(rig.name, 'state'))
        starts = FaultOnStart(rig.server, 20, 'late')
        rig.server.faults.inject(20, 'late')  # the next poll's reply: 'ready', 20 ms late
        started = client.call(rig.name, 'start')
        assert starts.fired.is_set() and not started.success, started.message
        assert wait_for(rig.probe.moving, 5.0)
        # The starter runs; no reading may say otherwise, and the motor stays "may run".
        assert client.spin_until(lambda: client.state(rig.name) in ('starting', 'running'),
                                 10.0)
        assert client.spin_until(  # the poll's late reply and the start's, both discarded
            lambda: int(status_values(client.diagnostics(rig.name)).get('late_replies', 0))
            >= 2, 10.0), client.diagnostics(rig.name)
        states = client.values(rig.name, 'state')[published_before:]
        moving = min(states.index(state) for state in ('starting', 'running') if state in states)
        assert 'ready' not in states[moving:], states  # nothing stale published
        values = status_values(client.diagnostics(rig.name))
        assert 'may be running' in values.get('motor', ''), values
        assert Lifecycle(client).transition('deactivate')
        assert wait_for(lambda: not rig.probe.moving(), 10.0), 'deactivate left it running'
        assert rig.probe.commands() == [MCD_START, MCD_STOP]
