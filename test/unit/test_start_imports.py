"""What a node start and a drive_bridge_ctl command import: nothing they do not use."""

import subprocess
import sys

import pytest

pytest.importorskip('rclpy', reason='ROS 2 (rclpy) from PyPI')


@pytest.mark.parametrize('module', ['drive_bridge.ros.node.process', 'drive_bridge.ros.ctl.cli',
                                    'drive_bridge.ros.record.cli'])
def test_sensor_msgs_and_numpy_are_imported_only_for_joints(module):
    """
    sensor_msgs brings numpy: about 0.1 s of CPU at every node start and every ctl command.

    Only a node with joints needs it (drive_bridge.ros.node.session imports the joints then).
    """
    probe = (f'import sys, {module}; '
             "print(sorted({m.split('.')[0] for m in sys.modules} & {'numpy', 'sensor_msgs'}))")
    done = subprocess.run([sys.executable, '-c', probe], capture_output=True, text=True,
                          timeout=60, check=True)
    assert done.stdout.strip() == '[]', done.stdout
