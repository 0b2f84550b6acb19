"""Release packaging: one version everywhere, the changelog, package.xml, the commands."""

from configparser import ConfigParser
from importlib import metadata
import os
import re
import subprocess
import sys
from xml.etree import ElementTree

import drive_bridge

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
COMMANDS = {'drive_bridge_node', 'drive_bridge_sim', 'drive-bridge', 'drive_bridge_plot',
            'drive_bridge_record', 'drive_bridge_ctl'}


def _package_xml() -> ElementTree.Element:
    return ElementTree.parse(os.path.join(ROOT, 'package.xml')).getroot()


def _read(name: str) -> str:
    with open(os.path.join(ROOT, name)) as stream:
        return stream.read()


def changelog_versions(text: str):
    """Return [(version, date)] of a catkin-style CHANGELOG.rst, checking its layout."""
    lines = text.splitlines()
    title = 'Changelog for package drive_bridge'
    assert lines[:3] == ['^' * len(title), title, '^' * len(title)]
    versions = []
    for index, line in enumerate(lines):
        match = re.fullmatch(r'(\d+\.\d+\.\d+) \((\d{4}-\d{2}-\d{2})\)', line)
        if match:
            assert lines[index + 1] == '-' * len(line), line
            versions.append((match.group(1), match.group(2)))
    return versions


def test_one_version_everywhere():
    version = _package_xml().findtext('version')
    assert drive_bridge.__version__ == version
    from_setup = subprocess.run([sys.executable, 'setup.py', '--version'], cwd=ROOT,
                                capture_output=True, text=True, check=True)
    assert from_setup.stdout.split()[-1] == version
    assert changelog_versions(_read('CHANGELOG.rst'))[0][0] == version


def test_changelog_covers_every_release_newest_first():
    versions = changelog_versions(_read('CHANGELOG.rst'))
    assert [name for name, _ in versions] == ['0.4.0', '0.3.0', '0.2.0', '0.1.0']
    dates = [date for _, date in versions]
    assert dates == sorted(dates, reverse=True)


def test_license_is_the_apache_2_text_package_xml_names():
    assert _package_xml().findtext('license') == 'Apache-2.0'
    text = _read('LICENSE')
    assert text.split()[:4] == ['Apache', 'License', 'Version', '2.0,']
    assert 'TERMS AND CONDITIONS FOR USE, REPRODUCTION, AND DISTRIBUTION' in text
    assert 'END OF TERMS AND CONDITIONS' in text and len(text) > 11000


def test_package_xml_names_what_colcon_test_needs():
    test_depends = {element.text for element in _package_xml().findall('test_depend')}
    assert {'python3-pytest', 'python3-pytest-timeout', 'python3-hypothesis',
            'mcap-ros2-support', 'ament_flake8', 'ament_pep257'} <= test_depends
    assert 'ament_copyright' not in test_depends  # there is no copyright test
    exec_depends = {element.text for element in _package_xml().findall('exec_depend')}
    assert {'python3-rosbags-pip', 'python3-matplotlib', 'rclpy'} <= exec_depends
    config = ConfigParser(interpolation=None)
    config.read(os.path.join(ROOT, 'setup.cfg'))
    assert 'timeout = 120' in _read('setup.cfg')
    for tier in ('unit', 'integration', 'ros'):
        assert re.search(rf'^\s*{tier}: ', config['tool:pytest']['markers'], re.MULTILINE)


def test_optional_modules_name_the_extra_and_the_rosdep_key_that_bring_them():
    from drive_bridge.extras import OPTIONAL
    exec_depends = {element.text for element in _package_xml().findall('exec_depend')}
    requirements = metadata.requires('drive_bridge')
    for module, source in OPTIONAL.items():
        assert source.rosdep_key in exec_depends, module
        assert any(re.fullmatch(rf'{module}\b[^;]*; extra == "{source.extra}"', requirement)
                   for requirement in requirements), module
    assert 'python3-yaml' in exec_depends  # imported by config.py and drive_bridge_plot
    assert any(re.fullmatch(r'PyYAML\b[^;]*', requirement) for requirement in requirements)


def test_console_scripts_go_where_ros2_run_finds_them():
    config = ConfigParser(interpolation=None)
    config.read(os.path.join(ROOT, 'setup.cfg'))
    assert config['install']['install_scripts'] == '$base/lib/drive_bridge'
    assert config['develop']['script_dir'] == '$base/lib/drive_bridge'
    scripts = {entry.name for entry in metadata.distribution('drive_bridge').entry_points
               if entry.group == 'console_scripts'}
    assert scripts == COMMANDS
