"""Unit tests of the MCD profile (decode, commands, tables) and the MCD behaviour model."""

from drive_bridge.devices import mcd
from drive_bridge.devices.contracts import FixedControl, SlowReadouts
from drive_bridge.errors import CommandRefused, ModelMismatch, ProtocolError
from drive_bridge.protocol.commands import Command
from drive_bridge.protocol.requests import ReadRegisters, WriteRegister
from drive_bridge.sim.mcd_model import McdModel, McdSimConfig, ModuleError
from fakes import drive_cycle
import pytest

MCD500_PRODUCT = (7 << 3) | 1


def status_block(status=0x43, trip=255, current=80, temperature=40, product=MCD500_PRODUCT,
                 protocol=1):
    return [[status, trip, current, temperature, product, protocol]]


def test_poll_is_one_read_of_40003_to_40008():
    requests, _ = drive_cycle(mcd.McdProfile(), [status_block()[0]])
    assert requests == [ReadRegisters(address=2, count=6)]


def test_register_addresses_are_number_minus_one():
    assert mcd.REGISTER['command'].address == 1
    assert mcd.REGISTER['starter_status'].address == 2
    assert mcd.REGISTER['serial_protocol_version'].address == 7
    assert mcd.REGISTER['first_parameter'].address == 8


def test_manual_example_status_running_and_trip_motor_overload():
    # Section 8.1: status read returns 3 (running); trip code read returns 2.
    profile = mcd.McdProfile('mcd500')
    reading = profile.decode(status_block(status=3, trip=2))
    assert reading.state == 'running'
    assert reading.trip_code == 2
    assert reading.trip_name == 'Motor overload (thermal model)'


def test_no_trip_255_is_published_as_zero():
    reading = mcd.McdProfile('mcd500').decode(status_block(trip=255))
    assert reading.trip_code == 0 and reading.trip_name == ''


@pytest.mark.parametrize('code, state', sorted(mcd.STATE_CODES.items()))
def test_every_state_code(code, state):
    assert mcd.McdProfile('mcd500').decode(status_block(status=code)).state == state


def test_status_bits_and_unknown_state():
    profile = mcd.McdProfile('mcd500')
    reading = profile.decode(status_block(status=0x63))  # running, above FLC, initialised
    assert reading.details['current_above_flc'] == 'True'
    assert reading.details['initialised'] == 'True'
    assert reading.warnings == ['motor current exceeds FLC']
    unknown = profile.decode(status_block(status=0x0C))
    assert unknown.state == 'unknown' and unknown.warnings


def test_tripped_state_is_a_fault():
    reading = mcd.McdProfile('mcd500').decode(status_block(status=6, trip=26))
    assert reading.fault == 'tripped: L1 phase loss'


def test_current_scale_and_temperature():
    reading = mcd.McdProfile('mcd500', current_scale=0.1).decode(status_block(current=468))
    assert reading.motor_current_a == pytest.approx(46.8)
    assert reading.motor_temperature_pct == 40.0


def test_mcd201_reports_no_current_or_temperature():
    product = 4 << 3
    reading = mcd.McdProfile('mcd201').decode(status_block(product=product))
    assert reading.motor_current_a is None and reading.motor_temperature_pct is None


@pytest.mark.parametrize('product_type, model', [(1, 'mcd3000'), (4, 'mcd202'), (7, 'mcd500')])
def test_auto_model_from_product_type(product_type, model):
    profile = mcd.McdProfile('auto')
    profile.decode(status_block(product=(product_type << 3) | 2))
    assert profile.model == model


def test_model_mismatch_is_a_clear_error():
    with pytest.raises(ModelMismatch, match='configured mcd3000 but the device reports MCD 500'):
        mcd.McdProfile('mcd3000').decode(status_block())
    with pytest.raises(ModelMismatch, match='unknown product type 3'):
        mcd.McdProfile('auto').decode(status_block(product=3 << 3))


def test_product_word_and_versions():
    assert mcd.decode_product_word(MCD500_PRODUCT) == (7, 1)
    details = mcd.McdProfile().decode(status_block(protocol=3)).details
    assert details['product_type'] == 'MCD 500'
    assert details['serial_protocol_version'] == '3'


def test_wrong_register_count_is_a_protocol_error():
    with pytest.raises(ProtocolError):
        mcd.McdProfile().decode([[1, 2, 3]])


@pytest.mark.parametrize('command, value', [
    (Command.START, 1), (Command.STOP, 2), (Command.RESET, 3), (Command.QUICK_STOP, 4),
    (Command.FORCED_COMMS_TRIP, 5)])
def test_commands_write_40002(command, value):
    plan = mcd.McdProfile().command_plan(command, FixedControl())
    assert plan.writes == (WriteRegister(1, value),)


def test_coast_stop_is_not_an_mcd_command():
    assert Command.COAST_STOP not in mcd.McdProfile().commands
    with pytest.raises(CommandRefused, match='no coast_stop command'):
        mcd.McdProfile().command_plan(Command.COAST_STOP, FixedControl())


def test_parameter_addresses():
    profile = mcd.McdProfile('mcd500')
    assert profile.parameter_address(1) == 8  # 40009, manual: par. 1-1 Motor FLC
    assert profile.parameter_address(4) == 11  # 40012, manual: par. 1-4 Current Limit
    with pytest.raises(CommandRefused, match='1-591'):
        profile.parameter_address(592)
    with pytest.raises(CommandRefused, match='no parameter registers'):
        mcd.McdProfile('mcd202').parameter_address(1)
    assert mcd.McdProfile('mcd3000').features.max_parameter == 60


def test_module_error_texts():
    text = mcd.module_error_text(9)
    assert 'network control disabled (Hand On mode or par. 3-2)' in text
    assert text.endswith('Modbus error 09')
    for code in range(1, 11):
        assert mcd.module_error_text(code).endswith(f'Modbus error {code:02d}')
    assert 'not in the module manual' in mcd.module_error_text(42)


def test_trip_names_per_model():
    assert mcd.trip_name(5, 'mcd201') == 'Frequency (mains supply)'
    assert mcd.trip_name(12, 'mcd201') == \
        'Input A trip (auxiliary input A) (not listed for mcd201)'
    assert mcd.trip_name(99) == 'unknown trip code 99'
    assert set(mcd.TRIP_CODES) >= {1, 2, 15, 16, 23, 33, 36}


# -- the behaviour model, driven with explicit time ----------------------------------------

def model(**settings):
    return McdModel(McdSimConfig(**settings), now_s=0.0)


def state_name(sim, now):
    sim.advance(now)
    return mcd.STATE_CODES[sim.state]


def test_model_start_run_stop_timing_and_current():
    sim = model(start_time_s=3.0, stop_time_s=2.0, motor_flc_a=100.0)
    sim.write_register(1, 1, now_s=1.0)
    assert state_name(sim, 1.1) == 'starting'
    assert sim.read_registers(4, 1, 1.2)[0] == pytest.approx(175, abs=1)  # rising
    assert sim.read_registers(4, 1, 1.5)[0] == 350  # current limit 350 % FLC
    assert state_name(sim, 3.9) == 'starting'
    assert state_name(sim, 4.1) == 'running'
    assert sim.read_registers(4, 1, 4.2)[0] == pytest.approx(80, abs=1)
    sim.write_register(1, 2, now_s=5.0)
    assert state_name(sim, 6.0) == 'stopping'
    assert state_name(sim, 7.1) == 'ready'
    assert sim.read_registers(4, 1, 7.2) == [0]


def test_model_thermal_rises_while_running_and_trips_at_105():
    sim = model(thermal_time_constant_s=300.0, run_current_pct=110.0)
    sim.write_register(1, 1, now_s=0.0)
    temperatures = [sim.read_registers(5, 1, float(t))[0] for t in (1, 3, 10, 60, 300)]
    assert temperatures == sorted(temperatures) and temperatures[-1] > 60
    assert sim.state == 3  # still running below the trip point
    for t in range(301, 2000, 10):
        sim.advance(float(t))
    assert sim.state == 6 and sim.trip_code == 2  # motor overload at 105 %
    cooled = sim.read_registers(5, 1, 3000.0)[0]
    assert cooled < 105  # cools once the motor is off


def test_model_quick_stop_and_reset():
    sim = model()
    sim.write_register(1, 1, 0.0)
    sim.write_register(1, 4, 0.5)
    assert state_name(sim, 0.6) == 'ready'
    sim.trip(26, 1.0)
    assert sim.read_registers(2, 2, 1.1) == [0x46, 26]
    sim.write_register(1, 1, 1.2)  # start while tripped: acknowledged, nothing happens
    assert state_name(sim, 1.3) == 'tripped'
    sim.write_register(1, 3, 1.4)
    assert state_name(sim, 1.5) == 'ready' and sim.trip_code == 255


def test_model_hand_on_refuses_start_and_stop_but_accepts_reset():
    sim = model()
    sim.hand_on = True
    for command in (1, 2, 4):
        with pytest.raises(ModuleError) as error:
            sim.write_register(1, command, 0.0)
        assert error.value.code == 9
    sim.trip(3, 0.1)
    sim.write_register(1, 3, 0.2)
    assert state_name(sim, 0.3) == 'ready'
    assert sim.read_registers(2, 6, 0.4)[0] & 0x0F == 1  # status still readable


def test_model_forced_comms_trip():
    sim = model()
    sim.write_register(1, 5, 0.0)
    assert sim.read_registers(2, 2, 0.1) == [0x46, 16]


@pytest.mark.parametrize('address, count, code', [
    (2, 7, 5),  # across 40008/40009
    (2, 126, 5),  # more than 125
    (1, 1, 3),  # 40002 is write-only
    (0, 1, 2),  # 40001 does not exist
    (8 + 591, 1, 7),  # beyond the last parameter
])
def test_model_read_errors(address, count, code):
    with pytest.raises(ModuleError) as error:
        model().read_registers(address, count, 0.0)
    assert error.value.code == code


@pytest.mark.parametrize('address, value, code', [(1, 6, 6), (2, 1, 4), (8 + 591, 1, 8)])
def test_model_write_errors(address, value, code):
    with pytest.raises(ModuleError) as error:
        model().write_register(address, value, 0.0)
    assert error.value.code == code


def test_model_mcd200_has_no_parameter_registers():
    sim = model(model='mcd202')
    with pytest.raises(ModuleError) as error:
        sim.read_registers(8, 1, 0.0)
    assert error.value.code == 2
    assert sim.read_registers(6, 1, 0.0) == [(4 << 3) | 1]


def test_model_parameters_manual_examples():
    sim = model()
    assert sim.read_registers(8, 1, 0.0) == [100]  # par. 1-1 Motor FLC = 100 A
    sim.write_register(11, 400, 0.0)  # par. 1-4 Current Limit = 400 %
    assert sim.read_registers(11, 1, 0.0) == [400]


def test_model_local_comms_error():
    sim = model()
    sim.local_comms_error = True
    with pytest.raises(ModuleError) as error:
        sim.read_registers(2, 6, 0.0)
    assert error.value.code == 10


def test_a_state_and_a_trip_come_from_the_poll_that_reads_them_never_from_40007_40008():
    # Issue 26's audit: 40007/40008 (product, protocol) are the MCD's slow readout, read once
    # a readout period; status and trip code (40003/40004) are read every poll with the rest.
    profile = mcd.McdProfile('mcd500', slow_readouts=SlowReadouts(10.0))
    requests, tripped = drive_cycle(profile, status_block(status=0x46, trip=2))  # slow: due
    assert requests == [ReadRegisters(address=2, count=6)]
    assert (tripped.state, tripped.trip_code) == ('tripped', 2)
    # At 1 s: reset at the starter; the slow readouts are not due.
    requests, reading = drive_cycle(profile, [status_block(status=0x41, trip=255)[0][:4]],
                                    now_s=1.0)
    assert requests == [ReadRegisters(address=2, count=4)]
    assert (reading.state, reading.trip_code, reading.trip_name) == ('ready', 0, '')
    _, reading = drive_cycle(profile, [status_block(status=0x44)[0][:4]],
                             now_s=1.0)  # a soft stop
    assert reading.state == 'stopping' and reading.details['product_type'] == 'MCD 500'
