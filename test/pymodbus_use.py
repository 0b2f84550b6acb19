"""
Keep the ``pymodbus`` marker honest: a test that makes a pymodbus transport must carry it.

scripts/test.sh runs only the tests marked ``pymodbus`` again with pymodbus 3.6.9 (Ubuntu
24.04's ``python3-pymodbus``). This plugin counts the ``ModbusTransport`` objects (the only
code that calls pymodbus) made during each test, its fixtures included, and fails the test's
teardown if it made one without the marker, so that no test that depends on pymodbus can be
left out of that tier. It counts in this process only: a test that runs pymodbus in a
subprocess is marked by hand.
"""

import functools
from typing import Any, Callable, Iterable, List

import pytest

MARKER = 'pymodbus'


def is_pymodbus_engine(value: Any) -> bool:
    return value == 'pymodbus'


def marked_params(values: Iterable[Any],
                  uses_pymodbus: Callable[[Any], bool] = is_pymodbus_engine) -> List[Any]:
    """Return ``values`` for a parametrisation, those that run pymodbus marked ``pymodbus``."""
    return [pytest.param(value, marks=pytest.mark.pymodbus) if uses_pymodbus(value) else value
            for value in values]


class PymodbusUse:
    """Count ModbusTransport objects as they are made, per test."""

    def __init__(self):
        from drive_bridge.transport.modbus import ModbusTransport
        self.made = 0
        original = ModbusTransport.__init__

        @functools.wraps(original)
        def counted_init(transport, *args, **kwargs):
            self.made += 1
            original(transport, *args, **kwargs)

        ModbusTransport.__init__ = counted_init
        self._undo = (ModbusTransport, original)
        self._made_before = 0

    def undo(self) -> None:
        cls, original = self._undo
        cls.__init__ = original

    @pytest.hookimpl(tryfirst=True)
    def pytest_runtest_setup(self, item):
        self._made_before = self.made

    @pytest.hookimpl(trylast=True)
    def pytest_runtest_teardown(self, item):
        made = self.made - self._made_before
        if made and item.get_closest_marker(MARKER) is None:
            pytest.fail(f'{item.nodeid} made {made} pymodbus transport(s) but is not marked '
                        f'@pytest.mark.{MARKER}: the pymodbus 3.6.9 tier (scripts/test.sh) '
                        'runs only marked tests', pytrace=False)


def register(config) -> None:
    """Count pymodbus transports in this test process (pymodbus is in every test venv)."""
    use = PymodbusUse()
    config.pluginmanager.register(use, 'pymodbus_use')
    config.add_cleanup(use.undo)
