"""RuntimeSettings: changes without a bus checked as with one; types kept after a refusal."""

from typing import Dict, List

import pytest

# rclpy is not in the pymodbus 3.6.9 venv (transport tiers only): skipped there.
parameters = pytest.importorskip('drive_bridge.ros.node.parameters',
                                 reason='ROS 2 (rclpy) from PyPI')
Parameter = pytest.importorskip('rclpy.parameter').Parameter
keep_declared_types, RuntimeSettings = parameters.keep_declared_types, parameters.RuntimeSettings


class Logger:
    def __init__(self):
        self.warnings: List[str] = []

    def warning(self, text: str) -> None:
        self.warnings.append(text)


class Declared:
    """The node's parameters before the change (unconfigured, or after a cleanup)."""

    def __init__(self, values: Dict[str, object]):
        self.values = values
        self.descriptors: Dict[str, object] = {}

    def has_parameter(self, name: str) -> bool:
        return name in self.values

    def get_parameter(self, name: str) -> Parameter:
        return Parameter(name, value=self.values[name])

    def set_descriptor(self, name: str, descriptor) -> None:
        self.descriptors[name] = descriptor


MONITOR_ONLY = {'mon.allow_control': False, 'mon.poll_rate': 20.0}


def set_without_bus(settings: RuntimeSettings, declared: Declared, **values):
    parameters = [Parameter(name.replace('__', '.'), value=value)
                  for name, value in values.items()]
    return settings.on_set(parameters, None, None, declared)


def test_control_is_not_switched_on_without_a_bus_where_the_site_forbids_it():
    logger = Logger()
    settings = RuntimeSettings(logger, allow_runtime_control_enable=False)
    result = set_without_bus(settings, Declared(MONITOR_ONLY), mon__allow_control=True)
    assert not result.successful
    assert 'allow_runtime_control_enable is false' in result.reason
    assert '\n' not in result.reason
    assert logger.warnings == [] and settings.changes_in_words == {}


def test_control_switched_on_without_a_bus_is_logged_and_kept_for_diagnostics():
    logger = Logger()
    settings = RuntimeSettings(logger, allow_runtime_control_enable=True)
    result = set_without_bus(settings, Declared(MONITOR_ONLY), mon__allow_control=True)
    assert result.successful
    assert len(logger.warnings) == 1
    assert logger.warnings[0].startswith('mon: control ENABLED at runtime')
    assert 'next configure' in logger.warnings[0]
    assert settings.changes_in_words['mon'].startswith('control enabled at runtime at ')


def test_control_switched_off_without_a_bus_is_kept_for_diagnostics():
    settings = RuntimeSettings(Logger(), allow_runtime_control_enable=False)
    declared = Declared({'mon.allow_control': True})
    assert set_without_bus(settings, declared, mon__allow_control=False).successful
    assert settings.changes_in_words['mon'].startswith('monitor only since a runtime change')


@pytest.mark.parametrize('value', [-5.0, float('nan'), 'fast'])
def test_a_bad_value_without_a_bus_is_refused_at_once_in_one_line(value):
    settings = RuntimeSettings(Logger(), allow_runtime_control_enable=True)
    result = set_without_bus(settings, Declared(MONITOR_ONLY), mon__poll_rate=value)
    assert not result.successful
    assert "'mon.poll_rate'" in result.reason and '\n' not in result.reason


def test_one_bad_value_refuses_the_whole_change_without_a_bus():
    logger = Logger()
    settings = RuntimeSettings(logger, allow_runtime_control_enable=True)
    result = set_without_bus(settings, Declared(MONITOR_ONLY), mon__allow_control=True,
                             mon__poll_rate=-5.0)
    assert not result.successful
    assert logger.warnings == [] and settings.changes_in_words == {}


def test_parameters_being_declared_by_the_configure_are_left_to_it():
    """Not declared yet: the configure declares them from the file and checks the result."""
    settings = RuntimeSettings(Logger(), allow_runtime_control_enable=False)
    result = set_without_bus(settings, Declared({}), mon__allow_control=True,
                             mon__poll_rate=-5.0)
    assert result.successful


def test_an_integer_for_a_double_is_refused_naming_the_parameter():
    settings = RuntimeSettings(Logger(), allow_runtime_control_enable=True)
    result = set_without_bus(settings, Declared(MONITOR_ONLY), mon__poll_rate=10)
    assert not result.successful
    assert result.reason == "parameter 'mon.poll_rate' = 10 is an integer: give a double (10.0)"


def test_a_refused_change_gives_each_runtime_parameter_its_descriptor_back():
    """The stored descriptor was typed as the refused value by rclpy: it is given back."""
    declared = Declared({'mon.poll_rate': 20.0, 'port': '/dev/null'})
    keep_declared_types([Parameter('mon.poll_rate', value='fast'),
                         Parameter('port', value=3)], declared)
    given_back = declared.descriptors['mon.poll_rate']
    assert given_back.name == 'mon.poll_rate' and given_back.dynamic_typing
    assert not given_back.read_only and given_back.floating_point_range
    assert list(declared.descriptors) == ['mon.poll_rate']  # bus settings are read-only


def test_the_on_set_callback_leaves_the_descriptors_alone():
    """The node gives the descriptors back after rclpy's whole set (set_parameters_atomically)."""
    declared = Declared(MONITOR_ONLY)
    settings = RuntimeSettings(Logger(), allow_runtime_control_enable=True)
    assert set_without_bus(settings, declared, mon__poll_rate=10.0).successful
    assert not set_without_bus(settings, declared, mon__poll_rate='fast').successful
    assert declared.descriptors == {}


@pytest.mark.parametrize('values, note', [
    ([False, True], None),  # the last value counts, as rclpy sets them: still in control
    ([True, False], 'monitor only since a runtime change'),
])
def test_one_allow_control_named_twice_in_one_change_is_noted_by_its_last_value(values, note):
    settings = RuntimeSettings(Logger(), allow_runtime_control_enable=False)
    declared = Declared({'mon.allow_control': True})
    parameters = [Parameter('mon.allow_control', value=value) for value in values]
    assert settings.on_set(parameters, None, None, declared).successful
    assert settings.changes_in_words.get('mon', '').startswith(note or '') and \
        (note is not None) == ('mon' in settings.changes_in_words)
