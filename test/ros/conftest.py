"""The ROS tier: one rclpy context per test process, in this process's own domain."""

import os
from typing import Dict, Optional

import pytest
import rclpy
from shared_rigs import end_shared_nodes, SharedRigs


@pytest.fixture(scope='session', autouse=True)
def ros_context():
    rclpy.init(domain_id=int(os.environ['ROS_DOMAIN_ID']))
    yield
    rclpy.try_shutdown()


@pytest.fixture(scope='session')
def rigs(tmp_path_factory):
    """Yield the shared nodes of this test process (test/ros/shared_rigs.py)."""
    shared = SharedRigs(tmp_path_factory.mktemp('rigs'))
    try:
        yield shared
    finally:
        shared.close()


def pytest_runtest_setup(item):
    """
    End the shared nodes (test/ros/shared_rigs.py) before a test that takes none.

    Such a test starts a node of its own, in this process's domain, with the same node and
    device names: the two would answer each other's clients.
    """
    if 'rigs' not in item.fixturenames:
        end_shared_nodes()


@pytest.hookimpl(trylast=True)
def pytest_collection_modifyitems(config, items):
    """
    In a run without pytest-xdist, run each rig's tests one after another (shared_rigs).

    Each then takes the node the one before left at rest, where a test with a node of its own
    between them would end it. A rig's tests move up to its first test's place; only the
    order changes. Under xdist, each rig's ``xdist_group`` does this on its worker.
    """
    if config.getoption('dist', default='no') != 'no' or hasattr(config, 'workerinput'):
        return
    places: Dict[str, list] = {}
    ordered: list = []
    for item in items:
        group = rig_group(item)
        if group is None:
            ordered.append([item])
        elif group in places:
            places[group].append(item)
        else:
            places[group] = [item]
            ordered.append(places[group])
    items[:] = [item for place in ordered for item in place]


def rig_group(item) -> Optional[str]:
    """Return the shared rig's ``xdist_group`` of a test (``rig_...``), or None."""
    for mark in item.iter_markers('xdist_group'):
        name = str(mark.args[0] if mark.args else mark.kwargs.get('name', ''))
        if name.startswith('rig_'):
            return name
    return None
