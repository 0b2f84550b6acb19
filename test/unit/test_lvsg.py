"""Unit tests of the LVSG codec (manual 002's tables) and the MCD 200 gateway profile."""

from drive_bridge.devices.contracts import FixedControl, SlowReadouts, TRIP_CODE_UNKNOWN
from drive_bridge.devices.lvsg import LvsgProfile
from drive_bridge.errors import CommandRefused, ModelMismatch
from drive_bridge.protocol import lvsg, words
from drive_bridge.protocol.commands import Command
from drive_bridge.protocol.lvsg import Control
from drive_bridge.protocol.requests import ReadRegisters, WriteRegister, WriteRegisters
from fakes import drive_cycle, FakeClock
import pytest


def test_control_bytes_of_the_profile():
    assert Control(fwd_run=True).encode(False) == bytes([0x01, 0x00])  # byte 0 bit 0
    assert Control(reset=True).encode(False) == bytes([0x08, 0x00])  # byte 0 bit 3
    assert Control(quick_stop=True).encode(False) == bytes([0x00, 0x10])  # byte 1 bit 4
    assert Control(fwd_run=True, parameter_request=3).encode(True) == bytes([1, 0, 3])
    assert Control.decode(bytes([0x09, 0x10, 2])) == Control(True, True, True, 2)


def test_status_bytes_and_percent_flc():
    status = lvsg.decode_status(bytes([0b011, 0x80 | 63]))
    assert status.ready and status.on and not status.fault and status.ramping
    assert status.current_raw == 63
    assert status.current_pct_flc == pytest.approx(200.0)  # "63 represents 200 % FLC"
    assert lvsg.current_raw_from_pct(100.0) == 32  # 100 * 0.315 = 31.5 -> 32
    assert lvsg.decode_status(bytes([0b100, 0])).fault
    with pytest.raises(ValueError):
        lvsg.decode_status(bytes(3))


def test_extended_answer_bytes():
    data = lvsg.encode_status(True, False, False, False, 0, answer=(3, 0x0123, False))
    status = lvsg.decode_status(data)
    assert (status.parameter, status.value, status.invalid_parameter) == (3, 0x0123, False)
    assert data[4:] == bytes([0x23, 0x01])  # low byte, then high byte
    invalid = lvsg.decode_status(lvsg.encode_status(True, False, False, False, 0, (9, 0, True)))
    assert invalid.invalid_parameter


def test_operating_parameters_and_tables():
    assert lvsg.product_type((4 << 3) << 8 | 7) == 4  # parameter 1: type 4 = MCD 200
    assert lvsg.split_state_parameter(2 << 8 | 0x46) == (2, 0x46)  # trip 2, fault, flags
    assert lvsg.MCD200_STATES[5] == 'restart_delay' and lvsg.MCD200_STATES[0] == 'unknown'
    assert lvsg.trip_name(16) == 'Communication failure between module and network'
    assert lvsg.trip_name(255) == ''
    assert lvsg.decode_diagnostic(bytes([3, 6, 0])) == 6  # length 3, trip code, reserved
    with pytest.raises(ValueError):
        lvsg.decode_diagnostic(bytes([2, 6]))


def test_register_packing_both_byte_orders():
    assert words.bytes_to_registers(bytes([1, 2, 3]), 'big') == [0x0102, 0x0300]
    assert words.bytes_to_registers(bytes([1, 2, 3]), 'little') == [0x0201, 0x0003]
    assert words.registers_to_bytes([0x0201, 0x0003], 3, 'little') == bytes([1, 2, 3])


def image(status: bytes, byte_order='big'):
    return words.bytes_to_registers(status, byte_order)


def poll(profile, input_bytes, output_bytes=None, control=None, now_s=0.0):
    """Run one poll cycle; return [(key, request)] and the reading."""
    keys = []

    def answer(request):
        if request == profile.gateway.read_back():
            keys.append('output')
            return image(output_bytes if output_bytes is not None else bytes(3))
        if request == profile.gateway.read_input():
            keys.append('input')
            return image(input_bytes)
        keys.append('write')
        return None
    requests, reading = drive_cycle(profile, answer, control, now_s)
    return list(zip(keys, requests)), reading


def answer(parameter, value, ready=True, on=False, fault=False, ramping=False):
    return lvsg.encode_status(ready, on, fault, ramping, 0, (parameter, value, False))


def written_control(request):
    values = [request.value] if isinstance(request, WriteRegister) else list(request.values)
    return Control.decode(words.registers_to_bytes(values, 3))


def test_first_poll_reads_the_output_image_back_then_cycles_parameters():
    profile = LvsgProfile('auto', input_register=0, output_register=100)
    items, _ = poll(profile, answer(0, 0))
    # First contact: no write before the image read back was judged (a Fwd Run in it).
    assert items == [('output', ReadRegisters(100, 2)), ('input', ReadRegisters(0, 3))]
    values = {1: (4 << 3) << 8 | 3, 2: 255 << 8 | 1, 3: 2222, 4: 111}
    for parameter in (1, 2, 3, 4):
        items, reading = poll(profile, answer(parameter, values[parameter]))
        # No command yet: only the register with the parameter request, never the control.
        assert items[0] == ('write', WriteRegister(101, parameter << 8))
    assert profile.model == 'mcd201'  # current 2222 and temperature 111 are its placeholders
    assert reading.motor_current_a is None and reading.state == 'ready'


def test_monitor_only_writes_nothing_not_even_the_parameter_request():
    profile = LvsgProfile('auto', input_register=0, output_register=100)
    for _ in range(3):
        items, _ = poll(profile, answer(0, 0), control=FixedControl(writes_allowed=False))
        assert not any(request.writes for _, request in items)


def test_a_fwd_run_left_in_the_gateway_for_a_stopped_starter_is_written_back_clear():
    profile = LvsgProfile('mcd202', input_register=0, output_register=100)
    items, reading = poll(profile, answer(0, 0), output_bytes=bytes([1, 0x10, 0]))
    assert [key for key, _ in items] == ['output', 'input', 'write']  # the clear first
    cleared = written_control(items[-1][1])
    assert not cleared.fwd_run and cleared.quick_stop  # only Fwd Run is cleared
    assert not reading.fault and profile.gateway.image.fwd_run is False
    items, _ = poll(profile, answer(0, 0))
    assert [key for key, _ in items] == ['write', 'input']  # the request alone from now on


def test_a_fwd_run_left_in_the_gateway_is_a_hazard_when_nothing_may_be_written():
    profile = LvsgProfile('mcd202', input_register=0, output_register=100)
    items, reading = poll(profile, answer(0, 0), output_bytes=bytes([1, 0, 0]),
                          control=FixedControl(writes_allowed=False))
    assert not any(request.writes for _, request in items)
    assert reading.fault.startswith('HAZARD: the gateway holds Fwd Run for a starter that is '
                                    'not on')


def test_a_running_starter_keeps_the_fwd_run_it_has():
    running = LvsgProfile('mcd202', input_register=0, output_register=100)
    items, _ = poll(running, answer(0, 0, ready=False, on=True), output_bytes=bytes([1, 0, 0]))
    assert [key for key, _ in items] == ['output', 'input']
    assert running.gateway.image.fwd_run is True
    items, _ = poll(running, answer(0, 0, ready=False, on=True))
    assert items[0] == ('write', WriteRegister(101, 1 << 8))  # the request, never the control
    assert running.gateway.image.fwd_run is True


def test_a_trip_asks_for_the_trip_code_next():
    profile = LvsgProfile('mcd202', input_register=0, output_register=100)
    poll(profile, answer(0, 0))
    _, reading = poll(profile, answer(0, 0, ready=False, fault=True))
    assert profile.operating.request == lvsg.PARAMETER_STATE
    assert reading.trip_code == TRIP_CODE_UNKNOWN  # tripped, code not read yet: never 0
    _, reading = poll(profile, answer(2, 2 << 8 | 6, ready=False, fault=True))
    assert (reading.state, reading.trip_code, reading.trip_name) == ('tripped', 2,
                                                                     'Motor overload')


def test_the_keepalive_writes_the_image_of_the_command_in_force():
    profile = LvsgProfile('mcd202', input_register=0, output_register=100)
    poll(profile, answer(0, 0))
    items, _ = poll(profile, answer(0, 0, ready=False, on=True),
                    control=FixedControl(Command.START))
    assert written_control(items[0][1]).fwd_run
    items, _ = poll(profile, answer(0, 0, ready=False, on=True),
                    control=FixedControl(Command.STOP))
    assert not written_control(items[0][1]).fwd_run


def test_commands_as_image_writes():
    profile = LvsgProfile('mcd202', input_register=0, output_register=100, module='basic')
    items, _ = poll(profile, lvsg.encode_status(False, True, False, False, 30),
                    output_bytes=bytes([1, 0]))
    items, _ = poll(profile, lvsg.encode_status(False, True, False, False, 30))
    assert items == [('input', ReadRegisters(0, 1))]  # basic, no command: nothing written
    control = FixedControl()
    quick = profile.command_plan(Command.QUICK_STOP, control).writes
    assert quick == (WriteRegister(100, 0x0110), WriteRegister(100, 0x0010))  # QS, then run off
    reset = profile.command_plan(Command.RESET, control).writes
    assert [words.registers_to_bytes([w.value], 2)[0] for w in reset] == [0x08, 0x00]
    assert profile.command_plan(Command.START, control).writes == (WriteRegister(100, 0x0100),)
    with pytest.raises(CommandRefused):
        profile.command_plan(Command.COAST_STOP, control)
    assert Command.COAST_STOP not in profile.commands
    extended = LvsgProfile('mcd202', input_register=0, output_register=100)
    assert isinstance(extended.command_plan(Command.START, control).writes[0], WriteRegisters)


def test_states_from_status_bits():
    profile = LvsgProfile('mcd202', input_register=0, output_register=100, module='basic')
    cases = [((True, False, False, False), 'ready'), ((False, True, False, False), 'running'),
             ((False, False, True, False), 'tripped'), ((False, False, False, False),
                                                        'not_ready')]
    for (ready, on, fault, ramping), state in cases:
        _, reading = poll(profile, lvsg.encode_status(ready, on, fault, ramping, 0),
                          bytes(2))
        assert reading.state == state
    # Without a state byte, a ramp's direction follows from the state before it.
    ramp = lvsg.encode_status(False, True, False, True, 40)
    _, reading = poll(profile, ramp, control=FixedControl(Command.START))
    assert reading.state == 'starting' and reading.details['motor_current_pct_flc'] == '127'
    _, reading = poll(profile, lvsg.encode_status(False, True, False, False, 40))
    assert reading.state == 'running'
    _, reading = poll(profile, ramp, control=FixedControl(Command.STOP))
    assert reading.state == 'stopping'
    _, reading = poll(profile, lvsg.encode_status(True, False, False, False, 0))
    # Started from the starter's own inputs: Fwd Run clear, still a start ramp.
    _, reading = poll(profile, ramp, control=FixedControl(Command.STOP))
    assert reading.state == 'starting'
    _, reading = poll(profile, lvsg.encode_status(False, False, True, False, 0))
    assert reading.trip_name.startswith('tripped (trip code not known')


def test_a_starter_started_by_a_fwd_run_it_kept_reads_starting_not_stopping():
    profile = LvsgProfile('mcd202', input_register=0, output_register=100, module='basic')
    _, reading = poll(profile, lvsg.encode_status(False, True, False, True, 40),
                      output_bytes=bytes([1, 0]))
    assert reading.state == 'starting'


def test_wrong_product_type_is_a_model_mismatch():
    profile = LvsgProfile('auto', input_register=0, output_register=100)
    poll(profile, answer(0, 0))
    with pytest.raises(ModelMismatch, match='product type 7'):
        poll(profile, answer(1, (7 << 3) << 8))


# -- the freshest information decides (issue 26) ---------------------------------------------
STATE_STARTING, STATE_RUNNING, STATE_STOPPING = 0x42, 0x43, 0x44  # flags: rotation validated
NO_TRIP_WORD = lvsg.NO_TRIP << 8


def slow_never_due():
    """Return slow readouts that are never due (for polls at time 0, as drive_cycle's)."""
    slow = SlowReadouts(1000.0)
    slow.due(0.0)  # the first poll that asks reads them: that one is gone
    return slow


def ready_mcd202(slow_readouts=None, **status):
    """Return an MCD 202 profile that has read product and state (ready, or ``status``)."""
    profile = LvsgProfile('mcd202', input_register=0, output_register=100,
                          slow_readouts=slow_readouts or slow_never_due())
    poll(profile, answer(0, 0, **status))  # first contact
    poll(profile, answer(1, (4 << 3) << 8 | 3, **status))
    return profile


def poll_until_state_byte(profile, clock, state_byte, control, **status):
    """
    Poll until the profile took ``state_byte``; return the reading.

    The slow readouts are due every poll and the gateway answers each request in the poll
    that wrote it (current 200 A, temperature 40 %, product MCD 200).
    """
    values = {1: (4 << 3) << 8 | 3, 2: NO_TRIP_WORD | state_byte, 3: 200, 4: 40}
    requested = [0]

    def reply(request):
        if request == profile.gateway.read_input():
            return image(answer(requested[-1], values.get(requested[-1], 0), **status))
        if isinstance(request, WriteRegisters):
            requested.append(request.values[1] >> 8)
        elif isinstance(request, WriteRegister):
            requested.append(request.value >> 8)
        return None
    for _ in range(10):
        clock.sleep(1.0)
        _, reading = drive_cycle(profile, reply, control, clock.now)
        if reading.details.get('mcd200_state') == str(state_byte & 0x0F):
            return reading
    raise AssertionError(f'state byte {state_byte:#x} never asked for')


def running_with_a_stale_starting_byte():
    """
    Return a started MCD 202 whose state byte was read during the start ramp, not since.

    The gateway answers the current and temperature requests only while it runs (it had not
    passed a newer request on yet), and the slow readouts' clock stands still.
    """
    clock = FakeClock()
    profile = ready_mcd202(SlowReadouts(1.0))
    start = FixedControl(Command.START)
    poll(profile, answer(2, NO_TRIP_WORD | 1))
    reading = poll_until_state_byte(profile, clock, STATE_STARTING, start, ready=False,
                                    on=True, ramping=True)
    assert reading.state == 'starting'
    for parameter in (3, 4, 3):  # running: the byte is not read again
        _, reading = poll(profile, answer(parameter, 80, ready=False, on=True), control=start)
        assert reading.state == 'running'
    return profile, clock


def test_a_soft_stop_is_stopping_though_the_state_byte_read_last_says_starting():
    profile, _ = running_with_a_stale_starting_byte()
    # The stop: On and Ramping again; the answer is parameter 4, the byte still the start's.
    items, reading = poll(profile, answer(4, 30, ready=False, on=True, ramping=True),
                          control=FixedControl(Command.STOP))
    assert reading.state == 'stopping'
    assert 'mcd200_state' not in reading.details  # not current: not shown as current
    assert profile.operating.request == lvsg.PARAMETER_STATE  # asked for next
    items, reading = poll(profile, answer(2, NO_TRIP_WORD | STATE_STOPPING, ready=False,
                                          on=True, ramping=True),
                          control=FixedControl(Command.STOP))
    assert written_control(items[0][1]).parameter_request == lvsg.PARAMETER_STATE
    assert reading.state == 'stopping' and reading.details['mcd200_state'] == '4'
    _, reading = poll(profile, answer(3, 0), control=FixedControl(Command.STOP))
    assert reading.state == 'ready'


def test_a_start_is_starting_though_the_state_byte_read_last_says_stopping():
    profile, clock = running_with_a_stale_starting_byte()
    stop = FixedControl(Command.STOP)
    reading = poll_until_state_byte(profile, clock, STATE_STOPPING, stop, ready=False, on=True,
                                    ramping=True)
    assert reading.state == 'stopping'
    for parameter in (3, 4):  # stopped: the byte is not read again
        _, reading = poll(profile, answer(parameter, 0), control=stop)
        assert reading.state == 'ready'
    _, reading = poll(profile, answer(3, 300, ready=False, on=True, ramping=True),
                      control=FixedControl(Command.START))
    assert reading.state == 'starting'


def test_a_stop_during_the_start_ramp_is_stopping_at_once():
    profile = ready_mcd202()
    poll(profile, answer(2, NO_TRIP_WORD | 1))
    ramp = {'ready': False, 'on': True, 'ramping': True}
    poll(profile, answer(3, 300, **ramp), control=FixedControl(Command.START))
    _, reading = poll(profile, answer(2, NO_TRIP_WORD | STATE_STARTING, **ramp),
                      control=FixedControl(Command.START))
    assert reading.state == 'starting'
    # The bridge drops its Fwd Run during the ramp: the status bits do not change (still
    # On and Ramping), the byte read before the stop does not count.
    _, reading = poll(profile, answer(3, 200, **ramp), control=FixedControl(Command.STOP))
    assert reading.state == 'stopping'


def test_a_trip_is_not_named_by_the_trip_code_of_an_earlier_one():
    profile = ready_mcd202()
    poll(profile, answer(2, NO_TRIP_WORD | 1))
    tripped = {'ready': False, 'fault': True}
    poll(profile, answer(3, 0, **tripped))
    _, reading = poll(profile, answer(2, 3 << 8 | 6, **tripped))
    assert (reading.trip_code, reading.trip_name) == (3, 'Motor thermistor')
    for parameter in (3, 4):  # reset: ready again, the byte (trip 3) is not read again
        _, reading = poll(profile, answer(parameter, 0))
        assert reading.state == 'ready' and reading.trip_code == 0
    _, reading = poll(profile, answer(3, 0, **tripped))  # another trip
    assert reading.trip_code == TRIP_CODE_UNKNOWN and 'not read yet' in reading.trip_name
    assert profile.operating.request == lvsg.PARAMETER_STATE
    _, reading = poll(profile, answer(2, 2 << 8 | 6, **tripped))
    assert (reading.trip_code, reading.trip_name) == (2, 'Motor overload')


def test_a_comms_failure_read_before_the_status_changed_is_not_reported_after_it():
    profile = ready_mcd202(ready=False)
    _, reading = poll(profile, answer(2, NO_TRIP_WORD | 0x80, ready=False))  # state 0, bit 7
    assert reading.state == 'unknown' and reading.fault.startswith('communication failure')
    _, reading = poll(profile, answer(3, 0))  # Ready: the module talks to the starter again
    assert reading.state == 'ready' and not reading.fault
