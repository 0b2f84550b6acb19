"""The simulator registry: one sim-side entry per simulated family, each naming real models."""

from drive_bridge.devices import mcd
from drive_bridge.devices.registry import FAMILIES
from drive_bridge.protocol import rtu
from drive_bridge.sim.devices import make_device
from drive_bridge.sim.registry import SIM_MODELS, SIMULATORS
import pytest


def test_each_simulator_is_a_registered_family_and_simulates_only_its_models():
    for name, simulator in SIMULATORS.items():
        assert name == simulator.family
        assert simulator.family in FAMILIES
        assert simulator.models
        assert set(simulator.models) <= set(FAMILIES[simulator.family].models) - {'auto'}


def test_the_simulated_models_are_the_starters_and_the_drives():
    assert list(SIM_MODELS) == [*mcd.MODEL_FEATURES, 'fc51', 'vlt5000', 'vlt6000']
    assert {SIM_MODELS[model] for model in SIM_MODELS} == {'mcd', 'fc', 'vlt'}


@pytest.mark.parametrize('model', sorted(SIM_MODELS))
def test_every_simulated_model_answers_a_read_at_its_address(model):
    device = make_device(model, now_s=0.0)
    if SIM_MODELS[model] == 'mcd':
        request = rtu.read_registers_request(20, 40003 - 40001, 1)  # the status register
    else:
        request = rtu.read_coils_request(20, 32, 16)  # coils 33-48: the status word
    reply = device.handle(request, 0.1)
    assert (reply.unit, reply.function) == (20, request.function)  # not an exception


def test_an_unknown_model_is_refused_with_the_models_allowed():
    with pytest.raises(ValueError, match='unknown simulated model .*allowed mcd'):
        make_device('mcd999')
