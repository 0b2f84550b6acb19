"""
Architecture: the import contracts of ``.importlinter`` hold, and they catch a violation.

``lint-imports`` checks the package's layers, that the ROS products (the node,
``drive_bridge_ctl``, the recorder) never import each other, that only ``ros`` imports rclpy
and only ``transport`` pymodbus and pyserial, that nothing imports test code, and that no
package has an import cycle among its modules. The second test breaks a copy of the package
on purpose and asserts that each contract so broken is reported: a checker that cannot fail
proves nothing.
"""

import os
import shutil
import subprocess
import sys
from typing import Dict

import pytest

pytest.importorskip('importlinter')

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CONFIG = os.path.join(ROOT, '.importlinter')

# lint-imports with the contracts in sys.argv[1]. lint-imports puts its working directory first
# on sys.path: run in a directory holding a copy of drive_bridge, it checks that copy.
_RUNNER = """
import sys
from importlinter.cli import lint_imports
sys.exit(lint_imports(config_filename=sys.argv[1], no_cache=True, no_logo=True))
"""

# One violation per contract: file (in drive_bridge/) -> line appended, and the contract's
# name as lint-imports reports it broken.
VIOLATIONS: Dict[str, str] = {
    'bus/events.py': 'import rclpy  # noqa',
    'config/params_file.py': 'from drive_bridge.config import model  # noqa',
    'devices/mcd.py': 'from drive_bridge.sim import mcd_model  # noqa',
    'protocol/crc.py': 'import serial  # noqa',
    'ros/ctl/session.py': 'from drive_bridge.ros.node import command_inputs  # noqa',
    'tools/cli_target.py': 'import soak_harness  # noqa',
    'transport/link.py': 'from drive_bridge.transport import engines  # noqa',
}
BROKEN = ('Layers: each imports only the layers below it',
          'The ROS products never import each other: the node, drive_bridge_ctl, the recorder',
          'Only ros imports rclpy and the ROS message packages',
          'Only transport imports pymodbus and pyserial',
          'Nothing in the package imports the tests, the benches or their helpers',
          'No import cycle between the modules of any one package',
          "config: the node's parameter names above the settings model")


def lint_imports(package_parent: str = ROOT) -> subprocess.CompletedProcess:
    """Run lint-imports with the repository's contracts on the drive_bridge in a directory."""
    return subprocess.run([sys.executable, '-c', _RUNNER, CONFIG], capture_output=True,
                          text=True, timeout=120, cwd=package_parent, stdin=subprocess.DEVNULL)


@pytest.mark.linter
def test_the_import_contracts_hold():
    result = lint_imports()
    assert result.returncode == 0, result.stdout + result.stderr
    assert '0 broken' in result.stdout


@pytest.mark.linter
def test_each_contract_catches_a_violation(tmp_path):
    shutil.copytree(os.path.join(ROOT, 'drive_bridge'), tmp_path / 'drive_bridge',
                    ignore=shutil.ignore_patterns('__pycache__'))
    for path, line in VIOLATIONS.items():
        with open(tmp_path / 'drive_bridge' / path, 'a') as stream:
            stream.write(f'\n{line}\n')
    result = lint_imports(str(tmp_path))
    report = ' '.join(result.stdout.split())  # lint-imports wraps long names
    assert result.returncode == 1, result.stdout + result.stderr
    assert f'{len(BROKEN)} broken' in report, result.stdout
    for name in BROKEN:
        assert report.count(name) == 2, name  # BROKEN in the list, then its violations
    assert 'drive_bridge.bus.events -> rclpy' in report
    assert 'drive_bridge.devices is not allowed to import drive_bridge.sim' in report
    assert 'drive_bridge.protocol.crc -> serial' in report
    assert 'drive_bridge.ros.ctl is not allowed to import drive_bridge.ros.node' in report
    assert 'drive_bridge.ros.ctl.session -> drive_bridge.ros.node.command_inputs' in report
    assert 'drive_bridge.tools.cli_target -> soak_harness' in report
    assert 'No cycles are allowed in drive_bridge.transport' in report
