"""
The optional dependencies, and the one line that says how to install a missing one.

``drive_bridge_record`` needs ``rosbags``; ``drive_bridge_plot`` needs ``rosbags`` and
``matplotlib``. A pip install gets them with the ``recording`` extra (setup.py), a ROS
workspace through rosdep from package.xml's keys. A command that misses one exits 2 with
:class:`MissingDependency`'s line instead of a traceback.
"""

from dataclasses import dataclass
import importlib


@dataclass(frozen=True)
class Source:
    """Where an optional module comes from: the pip extra and the rosdep key."""

    extra: str
    rosdep_key: str


OPTIONAL = {'rosbags': Source('recording', 'python3-rosbags-pip'),
            'matplotlib': Source('recording', 'python3-matplotlib')}


class MissingDependency(Exception):
    """An optional module is not installed; the text is the one line to show."""


def require(command: str, *modules: str) -> None:
    """Import ``modules``; raise MissingDependency naming the first one that is missing."""
    for module in modules:
        try:
            importlib.import_module(module)
        except ImportError:
            source = OPTIONAL[module]
            raise MissingDependency(
                f"{command} needs {module}: pip install 'drive_bridge[{source.extra}]' "
                f'(apt/rosdep: {source.rosdep_key})') from None
