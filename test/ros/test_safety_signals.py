"""
Safety cases 3, 4 and 10: exit signals and lifecycle transitions while motors run or start.

The node is started with SIGINT and SIGTERM at their defaults (a child of a background job
inherits SIGINT ignored). A start is held "in flight" by the simulated device: it executed
the start and holds back its reply (:class:`safety_helpers.ReplyHold`), or loses it. The
motor's end is read from the device.
"""

import random
import signal

from drive_bridge.sim.faults import FaultPlan
import pytest
from ros_helpers import write_params
from safety_helpers import (
    CpuHog, frames_to, HoldNext, MCD_START, MCD_STOP, ReplyHold, wait_for)
from safety_ros import (
    call_later, call_ok, clean_exit, Lifecycle, make_mixed_rig, make_rig, READY_S, Session,
    sigterm_round, start_behind_a_held_poll)

FAMILIES = ('mcd', 'fc', 'lvsg')
ROUNDS = 5
SIGNALS = {'SIGINT': signal.SIGINT, 'SIGTERM': signal.SIGTERM}


def more_frames(server, unit: int, count: int, timeout_s: float = 20.0) -> bool:
    """Wait until ``unit`` got ``count`` more requests (the polls go on meanwhile)."""
    target = frames_to(server, unit) + count
    return wait_for(lambda: frames_to(server, unit) >= target, timeout_s)


def start_in_flight(session: Session, hold: ReplyHold):
    """Send a start and return its future once the device executed it (reply held)."""
    client = session.client
    assert client.wait_state(session.rig.name, 'ready', READY_S)
    hold.arm()
    future = call_later(client, session.rig.name, 'start')
    assert client.spin_until(hold.seen.is_set, 15.0), 'the start never reached the device'
    return future


# -- case 3: signals and lifecycle with a start in flight -----------------------------------
@pytest.mark.parametrize('round_', range(ROUNDS))
@pytest.mark.parametrize('family', FAMILIES)
def test_exit_signal_with_a_start_in_flight_stops_the_motor(family, round_, tmp_path):
    """Case 3: SIGTERM/SIGINT while a start is on the wire: settled, stopped, exit 0."""
    number = (signal.SIGTERM, signal.SIGINT)[round_ % 2]
    lost = round_ in (2, 3)  # the reply is lost in these rounds, late in the others
    rig = make_rig(family)
    hold = ReplyHold(rig.probe, drop=lost, extra_s=0.15)
    rig.server.reply_hook = hold
    with Session(rig, tmp_path / 'inflight.yaml') as session:
        start_in_flight(session, hold)
        code, output = session.signal(number, after_send=hold.release)
    print(f'{family} {signal.Signals(number).name} reply {"lost" if lost else "late"}: '
          f'exit {code} after {session.exit_s:.2f} s')
    assert clean_exit(code, output), output
    assert rig.probe.start_edges() == 1
    assert wait_for(rig.probe.stopped, 5.0), 'the motor was left running'
    assert rig.probe.last_write_stops()


@pytest.mark.parametrize('family', FAMILIES)
def test_deactivate_with_a_start_in_flight_stops_and_writes_no_run_any_more(family, tmp_path):
    """Case 3: deactivate while a start is on the wire: inactive, stopped, no run word."""
    rig = make_rig(family)
    hold = ReplyHold(rig.probe, extra_s=0.15)
    rig.server.reply_hook = hold
    with Session(rig, tmp_path / 'deactivate.yaml') as session:
        client = session.client
        start = start_in_flight(session, hold)
        lifecycle = Lifecycle(client)
        change = lifecycle.begin('deactivate')
        hold.release()
        assert client.spin_until(change.done, 20.0), 'deactivate did not answer'
        assert change.result().success
        assert lifecycle.state() == 'inactive'
        assert wait_for(rig.probe.stopped, 5.0), 'the motor was left running'
        runs = rig.probe.run_writes()
        assert more_frames(rig.server, rig.probe.unit, 30)  # still polling while inactive
        assert rig.probe.run_writes() == runs, 'a run word was written after deactivate'
        assert rig.probe.stopped()
        assert client.spin_until(start.done, 15.0), 'the start in flight was never answered'
        print(f'start: {start.result().message}')
        refused = client.call(rig.name, 'start')
        assert not refused.success and 'inactive' in refused.message
        assert rig.probe.start_edges() == 1


@pytest.mark.parametrize('ending', ['SIGTERM', 'deactivate'])
@pytest.mark.parametrize('family', ['mcd', 'fc'])
def test_start_queued_behind_a_slow_poll_ends_stopped(family, ending, tmp_path):
    """Case 3: a start waiting for the bus when the node is told to stop: the motor ends still."""
    rig = make_rig(family)
    hold = HoldNext(rig.probe.unit)
    rig.server.reply_hook = hold
    with Session(rig, tmp_path / 'queued.yaml') as session:
        client = session.client
        start = start_behind_a_held_poll(client, rig, hold)
        if ending == 'deactivate':
            change = Lifecycle(client).begin('deactivate')
            hold.release()
            assert client.spin_until(change.done, 20.0) and change.result().success
            assert client.spin_until(start.done, 15.0), 'the queued start was never answered'
            print(f'start: {start.result().message}')
            assert more_frames(rig.server, rig.probe.unit, 30)
            code, output = session.signal(signal.SIGTERM)
        else:
            code, output = session.signal(signal.SIGTERM, after_send=hold.release)
    print(f'{family} {ending}: the device got {rig.probe.start_edges()} start(s)')
    assert clean_exit(code, output), output
    assert rig.probe.start_edges() <= 1
    assert wait_for(rig.probe.stopped, 5.0), 'the motor was left running'


def test_inactive_node_still_stops_a_starter_that_may_run(tmp_path):
    """Case 3: after deactivate, `stop` is still taken while a motor may run."""
    rig = make_rig('mcd')
    hold = ReplyHold(rig.probe, drop=True, wait_release=False)
    rig.server.reply_hook = hold
    with Session(rig, tmp_path / 'inactive.yaml') as session:
        client = session.client
        assert client.wait_state(rig.name, 'ready', READY_S)
        hold.arm()
        assert not client.call(rig.name, 'start').success  # executed, reply lost
        assert client.wait_state(rig.name, 'running', 10.0)
        model = rig.probe.model
        with rig.server.lock:
            model.hand_on = True  # the starter refuses network commands: the stop fails
        assert Lifecycle(client).transition('deactivate')
        assert rig.probe.commands() == [MCD_START]
        with rig.server.lock:
            model.hand_on = False
        response = call_ok(client, rig.name, 'stop')
        assert response.success, response.message
        assert rig.probe.commands()[:2] == [MCD_START, MCD_STOP]
        assert rig.probe.commands().count(MCD_START) == 1
        assert wait_for(lambda: not rig.probe.moving(), 5.0)
        refused = client.call(rig.name, 'stop')  # nothing may run now: inactive refuses
        assert not refused.success and 'inactive' in refused.message


# -- case 4: a second Ctrl-C during shutdown ------------------------------------------------
@pytest.mark.parametrize('sequence', [
    ('SIGINT', 'SIGINT'), ('SIGTERM', 'SIGINT'), ('SIGINT', 'SIGTERM'),
    ('SIGINT', 'SIGINT', 'SIGINT'), ('SIGTERM', 'SIGTERM')])
def test_repeated_exit_signals_still_stop_every_motor(sequence, tmp_path):
    """Case 4: signals 100 ms apart during shutdown: no traceback, exit 0, all stopped."""
    rig = make_mixed_rig()
    # exec'd, as a user starts it: its import threads exist (test/fork_server.py)
    with Session(rig, tmp_path / 'mixed.yaml', fresh=True) as session:
        client = session.client
        for name in rig.devices:
            assert client.wait_state(name, 'ready', READY_S), name
        for name in rig.devices:
            response = client.call(name, 'start', timeout_s=15.0)
            assert response.success, response.message
        for name in rig.devices:
            assert client.wait_state(name, 'running', 10.0), name
        # Slow replies: the stops take a while, so the later signals land among them.
        rig.server.faults.set_plan(FaultPlan(rate=1.0, kinds=('slow',), slow_s=0.1))
        code, output = session.signal(*(SIGNALS[name] for name in sequence), between_s=0.1)
    print(f'{"+".join(sequence)}: exit {code} after {session.exit_s:.2f} s')
    assert clean_exit(code, output), output
    for name, probe in rig.probes.items():
        assert probe.start_edges() == 1, name
        assert wait_for(probe.stopped, 5.0), f'{name} was left running'


# -- case 10: SIGTERM exits 0 without a traceback, with a CPU hog beside it -----------------
SIGTERM_ROUNDS = 10


def test_sigterm_exits_cleanly_under_load(tmp_path):
    """Case 10: SIGTERM at random moments with a CPU hog: exit 0, never a traceback."""
    rig = make_rig('fc')
    params = write_params(tmp_path / 'sigterm.yaml', rig.bus_settings(), rig.devices)
    chance = random.Random(10)
    failures = []
    try:
        with CpuHog():
            for index in range(SIGTERM_ROUNDS):
                failure = sigterm_round(params, rig, chance, index)
                if failure:
                    failures.append(failure)
    finally:
        rig.stop()
    print(f'{SIGTERM_ROUNDS - len(failures)} of {SIGTERM_ROUNDS} SIGTERMs exited cleanly')
    assert not failures, '\n\n'.join(failures)


def test_sigterm_with_the_line_unplugged_while_a_motor_runs_says_it_was_not_stopped(tmp_path):
    """Case 8: the adapter is gone: nothing can be sent, the stop says so at once, exit 0."""
    rig = make_rig('fc')
    with Session(rig, tmp_path / 'unplugged.yaml', timeout=0.2, backoff_max=0.5) as session:
        client = session.client
        assert client.wait_state(rig.name, 'ready', READY_S)
        assert client.call(rig.name, 'start').success
        assert wait_for(rig.probe.moving, 10.0)
        rig.server.unplug()
        assert client.wait_state(rig.name, 'offline', 10.0)
        code, output = session.signal(signal.SIGTERM)
    assert clean_exit(code, output), output
    assert 'NOT STOPPED: bus offline' in output, output
    assert session.exit_s < 3.0  # no stop waited out its timeout
    assert rig.probe.moving() and not rig.probe.last_write_stops()  # nothing could be sent
