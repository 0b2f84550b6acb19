"""The ROS tier: one rclpy context per test process, in this process's own domain."""

import os

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
