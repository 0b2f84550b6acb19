"""
The safety cases of the bridge, through the node; the motor is read from the simulated device.

Each test is one case of the safety issue (its number in the test's docstring), written
from the case and the ROS contract (``spec/ros_api.md``). Outcomes are judged by what the
simulated devices received (``commands_received``, ``control_words_received``, the
gateway's ``writes``, the recorded frames) and what their models do, never by what the
bridge says about itself.
"""

import signal
import time

from diagnostic_msgs.msg import DiagnosticStatus
from drive_bridge.protocol.lvsg import Control
from drive_bridge.sim.faults import FaultPlan
from drive_bridge.sim.mcd_model import STARTING
import pytest
from safety_helpers import (
    Babbler, frames_to, is_run_word, MCD_START, MCD_STOP, ReplyHold, sim_pty_master, spy_starts,
    wait_for, write_frames)
from safety_ros import (
    call_later, call_ok, clean_exit, diagnostics_seen, level_is, Lifecycle, make_mixed_rig,
    make_rig, READY_S, Session, status_values)
from shared_rigs import on_rig

REFERENCE_TIMEOUT_S = 3.0


def more_frames(rig, count: int, timeout_s: float = 20.0) -> bool:
    """Wait until the device got ``count`` more requests (polls go on meanwhile)."""
    unit = rig.probe.unit
    target = frames_to(rig.server, unit) + count
    return wait_for(lambda: frames_to(rig.server, unit) >= target, timeout_s)


# -- case 2: a start whose reply is lost ----------------------------------------------------
@pytest.mark.parametrize('family', ['fc', 'vlt', 'lvsg'])
def test_cyclic_start_with_lost_reply_ends_stopped_and_is_never_repeated(family, tmp_path):
    """Case 2: a cyclic device's start got no reply: it ends stopped, never a 2nd start."""
    extra = {'reference_timeout': REFERENCE_TIMEOUT_S} if family != 'lvsg' else {}
    rig = make_rig(family, **extra)
    hold = ReplyHold(rig.probe, drop=True, wait_release=False)
    rig.server.reply_hook = hold
    with Session(rig, tmp_path / 'lost.yaml') as session:
        client = session.client
        assert client.wait_state(rig.name, 'ready', READY_S)
        hold.arm()
        response = client.call(rig.name, 'start', timeout_s=15.0)
        since = len(client.messages['/diagnostics'])  # from the failure answer on
        assert hold.seen.is_set(), 'the start never reached the device'
        assert not response.success, response.message
        print(f'answer: {response.message}')
        # The drive gets a stop within the reference timeout (or sooner), and stops.
        assert wait_for(rig.probe.last_write_stops, REFERENCE_TIMEOUT_S + 5.0, 0.01)
        took_s = time.monotonic() - hold.seen_at_s
        print(f'{family}: a stop reached the device {took_s:.2f} s after the start')
        assert took_s < REFERENCE_TIMEOUT_S
        assert wait_for(rig.probe.stopped, 10.0)
        # /diagnostics said the motor may be running.
        warn = diagnostics_seen(client, rig.name, level_is(DiagnosticStatus.WARN),
                                since=since)
        assert warn is not None, 'no WARN while the motor may be running'
        print(f'WARN: {warn.message}')
        assert more_frames(rig, 40)  # the cycle goes on: a repeated start would show
        assert rig.probe.start_edges() == 1
        assert rig.probe.run_writes() == 1, 'the keepalive repeated the failed start'
        assert rig.probe.stopped()
        code, output = session.signal(signal.SIGTERM)
    assert clean_exit(code, output), output


@pytest.mark.parametrize('ending', ['sigterm', 'deactivate'])
def test_mcd_start_with_lost_reply_counts_as_running_until_stopped(ending, tmp_path):
    """Case 2: an MCD start without reply may run: WARN, never repeated, stopped at the end."""
    rig = make_rig('mcd')
    hold = ReplyHold(rig.probe, drop=True, wait_release=False)
    rig.server.reply_hook = hold
    with Session(rig, tmp_path / 'lost.yaml') as session:
        client = session.client
        assert client.wait_state(rig.name, 'ready', READY_S)
        hold.arm()
        response = client.call(rig.name, 'start', timeout_s=15.0)
        since = len(client.messages['/diagnostics'])  # from the failure answer on
        assert hold.seen.is_set() and not response.success, response.message
        assert client.wait_state(rig.name, 'running', 10.0)  # the starter did start
        warn = diagnostics_seen(client, rig.name, level_is(DiagnosticStatus.WARN),
                                since=since)
        assert warn is not None, 'no WARN while the motor may be running'
        print(f'WARN: {warn.message}')
        assert more_frames(rig, 30)
        assert rig.probe.commands() == [MCD_START], 'the start was repeated'
        if ending == 'deactivate':
            assert Lifecycle(client).transition('deactivate')
            assert rig.probe.commands()[:2] == [MCD_START, MCD_STOP]
        code, output = session.signal(signal.SIGTERM)
    assert clean_exit(code, output), output
    commands = rig.probe.commands()  # a stop without reply is sent again at shutdown
    assert commands[:2] == [MCD_START, MCD_STOP] and set(commands[1:]) == {MCD_STOP}, commands
    assert wait_for(lambda: not rig.probe.moving(), 5.0)


# -- case 1: a babbling line ----------------------------------------------------------------
def more_diagnostics(client, count: int, timeout_s: float = 20.0) -> bool:
    """Spin until ``count`` more /diagnostics messages came (5 a second here)."""
    target = len(client.messages['/diagnostics']) + count
    return client.spin_until(lambda: len(client.messages['/diagnostics']) >= target, timeout_s)


def test_babbling_line_never_lets_a_failed_start_out_later(tmp_path):
    """
    Case 1: starts asked for while a device babbles: none reaches the starter later.

    Modbus RTU only: a babbler writing to the pty beside the AP ASCII simulator makes the
    simulator's own writes fail now and then (EAGAIN: the kernel's pty buffer memory), and
    its thread dies on that; the AP ASCII transport is tested on a babbling line in
    test/integration/test_safety_bus.py.
    """
    rig = make_rig('mcd')
    starts = spy_starts(rig.probe.model)
    calls = []  # (sent, answered, response), one call at a time
    with Session(rig, tmp_path / 'babble.yaml', timeout=0.3) as session:
        client = session.client
        assert client.wait_state(rig.name, 'ready', READY_S)
        since = len(client.messages['/diagnostics'])
        with Babbler(sim_pty_master(rig.server)):
            error = diagnostics_seen(client, rig.name, level_is(DiagnosticStatus.ERROR),
                                     15.0, since)
            assert error is not None, 'a babbling line is no ERROR in /diagnostics'
            print(f'while babbling: {error.message}')
            babble_until = time.monotonic() + 6.0
            while time.monotonic() < babble_until:
                sent = time.monotonic()
                response = client.call(rig.name, 'start', timeout_s=20.0)
                calls.append((sent, time.monotonic(), response))
                client.spin_until(lambda: False, 0.3)  # a pause between calls
            last = client.diagnostics(rig.name)
        quiet = time.monotonic()
        # The line is quiet again: the node finds the starter, the cycle goes on.
        assert client.spin_until(lambda: client.state(rig.name) in ('ready', 'starting',
                                                                    'running'), 20.0)
        assert more_diagnostics(client, 20)
        code, output = session.signal(signal.SIGTERM)
    assert clean_exit(code, output), output
    print(f'{len(calls)} start calls while babbling, {sum(c[2].success for c in calls)} '
          f'acknowledged; slowest answer {max(c[1] - c[0] for c in calls):.2f} s; '
          f'starts that reached the starter: {len(starts)}')
    print(f'babble counters: {status_values(last).get("errors_babble")} babble, '
          f'{status_values(last).get("errors")} errors in all')
    for message in sorted({c[2].message for c in calls}):
        print(f'  {message}')
    for executed in starts:
        owners = [call for call in calls if call[0] <= executed <= call[1]]
        assert owners, (f'a start reached the starter {executed - quiet:+.2f} s after the '
                        'babbling ended, outside every call')
        response = owners[0][2]
        assert 'nothing sent' not in response.message and \
            'never sent' not in response.message, \
            f'the answer said "{response.message}" but the start reached the starter'


# -- case 7: a tripped drive and its keepalive ----------------------------------------------
@pytest.mark.parametrize('family', [on_rig(family, family) for family in ('fc', 'vlt')])
def test_trip_ends_the_run_and_a_reset_at_the_drive_does_not_restart(family, rigs):
    """Case 7: after a trip the drive gets a stop word; an LCP reset does not restart it."""
    with rigs.session(family) as session:
        client, rig = session.client, session.rig
        probe, model, server = rig.probe, rig.probe.model, rig.server
        assert client.wait_state(rig.name, 'ready', READY_S)
        assert client.call(rig.name, 'start').success
        assert client.wait_state(rig.name, 'running', 10.0)
        with server.lock:
            tripped_at = len(model.control_words_received)
            model.trip(5, server.clock())  # over current
        assert client.wait_state(rig.name, 'tripped', 10.0)
        assert wait_for(lambda: any(not is_run_word(word)
                                    for word in probe.words()[tripped_at:]), 10.0), \
            'the drive never got a stop word after the trip'
        stop_at = tripped_at + next(index for index, word in
                                    enumerate(probe.words()[tripped_at:])
                                    if not is_run_word(word))
        with server.lock:  # the technician resets the trip at the drive's LCP
            model.alarm_word = 0
            model.trip_locked = False
        reset_states = len(client.values(rig.name, 'state'))
        moving = []
        target = frames_to(server, probe.unit) + 40

        def watched() -> bool:
            moving.append(probe.moving())
            return frames_to(server, probe.unit) >= target

        assert wait_for(watched, 20.0)
        assert not any(moving), 'the drive restarted after the reset at its LCP'
        late_runs = [hex(word) for word in probe.words()[stop_at:] if is_run_word(word)]
        assert not late_runs, f'run words after the trip ended the run: {late_runs}'
        assert client.wait_state(rig.name, 'ready', 10.0)
        after_reset = client.values(rig.name, 'state')[reset_states:]
        assert 'running' not in after_reset and 'starting' not in after_reset, after_reset


# -- case 8: LVSG Fwd Run left in the gateway -----------------------------------------------
def leave_fwd_run(rig) -> None:
    """Leave Fwd Run set in the gateway, as a previous master did; the starter is not on."""
    with rig.server.lock:
        rig.probe.slave.control = Control(fwd_run=True)


@pytest.mark.parametrize('family', ['lvsg_basic', 'lvsg'])
def test_fwd_run_left_in_the_gateway_is_cleared_before_anything_else(family, tmp_path):
    """Case 8: at first contact, Fwd Run is written back clear before any other write."""
    rig = make_rig(family)
    leave_fwd_run(rig)
    with Session(rig, tmp_path / 'fwd_run.yaml') as session:
        assert session.client.wait_state(rig.name, 'ready', READY_S)
        assert more_frames(rig, 20)
        images = rig.probe.images()
        assert images, 'nothing written: Fwd Run is still held in the gateway'
        print(f'first writes: {[rig.server.stats.frames[0].hex()]} '
              f'{[f.hex() for f in write_frames(rig.server, 1)[:3]]}')
        assert not images[0].fwd_run, \
            f'the first write left Fwd Run set in the gateway ({images[0]})'
        assert not rig.probe.slave.control.fwd_run
        assert rig.probe.start_edges() == 0


@pytest.mark.parametrize('family', ['lvsg_basic', 'lvsg'])
def test_fwd_run_left_on_a_tripped_starter_never_starts_it(family, tmp_path):
    """Case 8: Fwd Run held for a tripped starter: cleared, and a reset does not start it."""
    rig = make_rig(family)
    model, server = rig.probe.model, rig.server
    with server.lock:
        model.trip(3, server.clock())  # motor thermistor
    leave_fwd_run(rig)
    with Session(rig, tmp_path / 'tripped.yaml') as session:
        client = session.client
        assert client.wait_state(rig.name, 'tripped', READY_S)
        assert wait_for(lambda: not rig.probe.slave.control.fwd_run, 10.0), \
            'Fwd Run is still held for the tripped starter'
        assert call_ok(client, rig.name, 'reset').success
        assert client.wait_state(rig.name, 'ready', 10.0)
        assert more_frames(rig, 20)
        assert rig.probe.start_edges() == 0, 'the reset started the motor'
        assert not rig.probe.moving()


def test_fwd_run_left_in_the_gateway_is_an_error_when_monitor_only(tmp_path):
    """Case 8: monitor only: nothing written, /diagnostics ERROR with the hazard in words."""
    rig = make_rig('lvsg', allow_control=False)
    leave_fwd_run(rig)
    with Session(rig, tmp_path / 'fwd_run.yaml') as session:
        status = diagnostics_seen(session.client, rig.name,
                                  level_is(DiagnosticStatus.ERROR), READY_S)
        assert status is not None
        print(f'ERROR: {status.message}')
        assert 'Fwd Run' in status.message
        assert more_frames(rig, 20)
        assert write_frames(rig.server, 1) == []
        assert rig.probe.start_edges() == 0


def states_while(client, name: str, busy) -> list:
    """Return the states published while ``busy()`` holds."""
    first = len(client.values(name, 'state'))
    while busy():
        client.spin_until(lambda: False, 0.02)
    return client.values(name, 'state')[first:]


def test_basic_module_never_says_stopping_for_a_starter_that_is_starting(tmp_path):
    """Case 8: basic module: a starter starting (through the node or locally) is not stopping."""
    rig = make_rig('lvsg_basic')
    model, server = rig.probe.model, rig.server
    with server.lock:
        model.config.start_time_s = 2.0
    with Session(rig, tmp_path / 'basic.yaml') as session:
        client = session.client
        assert client.wait_state(rig.name, 'ready', READY_S)

        def starting() -> bool:
            with server.lock:
                model.advance(server.clock())
                return model.state == STARTING

        for _ in range(2):
            first = len(client.values(rig.name, 'state'))
            assert client.call(rig.name, 'start').success
            assert client.wait_state(rig.name, 'running', 10.0)
            through_node = client.values(rig.name, 'state')[first:]
            assert 'stopping' not in through_node, through_node
            assert call_ok(client, rig.name, 'stop').success
            assert client.wait_state(rig.name, 'ready', 10.0)
        with server.lock:  # a start from the starter's own inputs
            model.write_register(1, MCD_START, server.clock())
        local = states_while(client, rig.name, starting)
        print(f'states during a local start: {local}')
        assert local, 'no reading while the starter was starting'
        assert 'stopping' not in local, local


# -- case 9: concurrent service calls and the reference topic -------------------------------
def test_concurrent_calls_on_a_slow_bus_do_not_starve_the_reference_topic(tmp_path):
    """Case 9: 16 concurrent calls at a time, slow bus, 10 Hz references: no deadman stop."""
    rig = make_mixed_rig()
    for name in ('starter', 'fan', 'mixer'):
        rig.devices[name]['poll_rate'] = 5.0
    rig.devices['conv']['reference_timeout'] = 1.0
    drive = rig.probes['conv']
    with Session(rig, tmp_path / 'busy.yaml') as session:
        client = session.client
        for name in rig.devices:
            assert client.wait_state(name, 'ready', READY_S), name
        published = []

        def publish() -> None:
            client.publish_reference('conv', 40.0)
            published.append(time.monotonic())

        timer = client.node.create_timer(0.1, publish)
        assert client.spin_until(lambda: len(published) >= 5, 5.0)
        assert client.call('conv', 'start').success
        assert client.wait_state('conv', 'running', 10.0)
        started_at = len(drive.words())
        rig.server.faults.set_plan(FaultPlan(rate=1.0, kinds=('slow',), slow_s=0.1))
        targets = [('starter', 'reset'), ('starter', 'stop'), ('mixer', 'reset'),
                   ('fan', 'reset')] * 4
        moving, answers = [], []
        until = time.monotonic() + 8.0
        while time.monotonic() < until:
            futures = [call_later(client, name, command) for name, command in targets]
            assert client.spin_until(
                lambda: moving.append(drive.moving()) or all(f.done() for f in futures),
                30.0), 'calls left unanswered'
            answers += [future.result() for future in futures]
        client.node.destroy_timer(timer)
        rig.server.faults.set_plan(FaultPlan())
        gaps = [b - a for a, b in zip(published, published[1:])]
        print(f'{len(answers)} calls, {sum(a.success for a in answers)} acknowledged; '
              f'reference gaps max {max(gaps):.2f} s')
        if max(gaps) > 0.8:  # then a deadman stop would be right: nothing to judge
            pytest.skip(f'the machine stalled the publisher of this test {max(gaps):.2f} s')
        words = drive.words()[started_at:]
        stops = [hex(word) for word in words if not is_run_word(word)]
        assert not stops, f'the drive got stop words: {stops}'
        assert all(moving), 'the drive stopped during the calls'
        status = diagnostics_seen(client, 'conv', lambda status: True,
                                  since=len(client.messages['/diagnostics']) - 1)
        assert status_values(status).get('deadman_stops') == '0'
