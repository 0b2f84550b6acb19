"""The Wireshark dissectors are installed with the package and in share/ (colcon, apt)."""

import glob
import os
import shutil
import subprocess
import sys

from drive_bridge.tools.cli_wireshark import dissector_files

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SOURCES = ('setup.py', 'setup.cfg', 'package.xml', 'resource', 'config', 'launch',
           'drive_bridge')


def test_setup_installs_every_dissector_in_the_package_and_in_share(tmp_path):
    source = tmp_path / 'source'
    for name in SOURCES:
        path = os.path.join(ROOT, name)
        if os.path.isdir(path):
            shutil.copytree(path, source / name,
                            ignore=shutil.ignore_patterns('__pycache__'))
        else:
            os.makedirs(source, exist_ok=True)
            shutil.copy(path, source / name)
    root = tmp_path / 'root'
    subprocess.run([sys.executable, 'setup.py', '-q', 'install', '--root', str(root),
                    '--prefix', '/opt/drive_bridge', '--single-version-externally-managed'],
                   cwd=source, capture_output=True, text=True, timeout=120, check=True)
    shipped = sorted(entry.name for entry in dissector_files())
    assert shipped == ['danfoss_ap_ascii.lua', 'danfoss_fc.lua', 'danfoss_lvsg.lua']
    prefix = root / 'opt' / 'drive_bridge'
    in_share = sorted(os.listdir(prefix / 'share' / 'drive_bridge' / 'wireshark'))
    in_package = sorted(os.path.basename(path) for path in glob.glob(
        str(prefix / 'lib' / 'python*' / '*-packages' / 'drive_bridge' / 'wireshark' / '*')))
    assert in_share == shipped and in_package == shipped
