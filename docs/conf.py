"""
Sphinx configuration of the drive_bridge manual.

Built by ``scripts/docs.sh`` (warnings are errors) and, for docs.ros.org, by rosdoc2, which
copies this directory (``rosdoc2.yaml``: ``sphinx_sourcedir: docs``) and runs this file from
its own wrapper: paths are taken from this file's directory, and the package is found on
``sys.path`` (rosdoc2 puts the package's directory there).
"""

import importlib
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, os.path.join(HERE, '_ext'))
if os.path.isfile(os.path.join(ROOT, 'package.xml')):  # a checkout: the package beside docs/
    sys.path.insert(0, ROOT)

import drive_bridge  # noqa: E402 - after the path is set

project = 'drive_bridge'
author = 'drive_bridge developers'
copyright = 'drive_bridge developers, Apache-2.0'  # noqa: A001 - Sphinx's name
release = drive_bridge.__version__
version = '.'.join(release.split('.')[:2])

extensions = ['myst_parser', 'drive_bridge_docs']
try:  # the command references; drive_bridge_docs stands in with --help without it
    importlib.import_module('sphinxarg.ext')
    extensions.append('sphinxarg.ext')
except ImportError:
    pass

# The parsers of drive_bridge_record and drive_bridge_ctl sit beside their rclpy code: import
# them with the ROS modules that are not installed mocked (a docs build needs no ROS), as
# rosdoc2 mocks the missing exec_depends for autodoc.
ROS_MODULES = ('rclpy', 'rcl_interfaces', 'std_msgs', 'std_srvs', 'sensor_msgs',
               'diagnostic_msgs', 'lifecycle_msgs', 'ament_index_python', 'rosbags')


def _missing(name: str) -> bool:
    try:
        importlib.import_module(name)
    except ImportError:
        return True
    return False


from sphinx.ext.autodoc.mock import mock  # noqa: E402 - Sphinx is there when this runs

with mock([name for name in ROS_MODULES if _missing(name)]):
    for module in ('drive_bridge.ros.record.cli', 'drive_bridge.ros.ctl.cli'):
        importlib.import_module(module)

source_suffix = {'.md': 'markdown'}
root_doc = 'index'
exclude_patterns = ['_build', '_ext', 'Thumbs.db', '.DS_Store']
myst_heading_anchors = 4
myst_enable_extensions = ['colon_fence', 'deflist']
smartquotes = False  # options stay '--config', not an en dash
suppress_warnings = []
nitpicky = True

html_theme = 'sphinx_rtd_theme'
html_theme_options = {'navigation_depth': 3, 'collapse_navigation': False}
html_static_path = ['_static']
html_css_files = ['drive_bridge.css']
html_title = f'drive_bridge {release}'

# rosdoc2 drops extensions it does not ship unless a package allows them.
rosdoc2_settings = {'allow_other_extensions': True, 'override_theme': True}
