"""Simulated MCD buses for the integration tier."""


from drive_bridge.sim.mcd_device import make_mcd_server
import pytest


def make_server(models):
    return make_mcd_server(models, start_time_s=0.5, stop_time_s=0.5)


@pytest.fixture
def sim_bus():
    """MCD 500 at 20 and MCD 202 at 21 on one simulated line (22 is not served)."""
    server = make_server({20: 'mcd500', 21: 'mcd202'})
    server.open_pty()
    server.start()
    yield server
    server.stop()
