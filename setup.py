"""Build script of the drive_bridge ament_python package."""

from glob import glob
import os
from xml.etree import ElementTree

from setuptools import find_packages, setup

PACKAGE = 'drive_bridge'
HERE = os.path.dirname(os.path.abspath(__file__))
# One version: package.xml's (ROS tools read it); drive_bridge.__version__ is checked against it.
VERSION = ElementTree.parse(os.path.join(HERE, 'package.xml')).findtext('version')

setup(
    name=PACKAGE,
    version=VERSION,
    packages=find_packages(include=['drive_bridge', 'drive_bridge.*']),  # not test/, bench/
    # the Wireshark dissectors (docs/wireshark.md): in the package for drive-bridge wireshark
    package_data={PACKAGE: ['wireshark/*.lua']},
    data_files=[
        ('share/ament_index/resource_index/packages', [f'resource/{PACKAGE}']),
        (f'share/{PACKAGE}', ['package.xml']),
        (f'share/{PACKAGE}/config', glob('config/*.yaml')),
        (f'share/{PACKAGE}/config/ros2_control', glob('config/ros2_control/*')),
        (f'share/{PACKAGE}/launch', glob('launch/*.launch.py')),
        (f'share/{PACKAGE}/wireshark', glob(f'{PACKAGE}/wireshark/*.lua')),
    ],
    # PyYAML: parameter and backup files, bag metadata (package.xml: python3-yaml)
    install_requires=['setuptools', 'pymodbus>=3.6.9', 'pyserial>=3.5', 'tqdm>=4.66',
                      'PyYAML>=5.4'],
    # drive_bridge_record and drive_bridge_plot; drive_bridge/extras.py names them when missing
    extras_require={'recording': ['rosbags>=0.10.11', 'matplotlib>=3.6']},
    tests_require=['pytest'],  # colcon test runs pytest when this names it
    zip_safe=True,
    maintainer='drive_bridge developers',
    maintainer_email='dev@drive-bridge.invalid',
    description='ROS 2 driver for Danfoss soft starters and frequency drives over RS-485',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'drive_bridge_node = drive_bridge.ros.node.entry:main',
            'drive_bridge_sim = drive_bridge.sim.cli:main',
            'drive-bridge = drive_bridge.tools.cli:main',
            'drive_bridge_plot = drive_bridge.tools.plot_recording:main',
            'drive_bridge_record = drive_bridge.ros.record.cli:main',
            'drive_bridge_ctl = drive_bridge.ros.ctl.cli:main',
        ],
    },
)
