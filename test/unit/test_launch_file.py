"""
The launch file, loaded with stand-ins for launch and launch_ros (not on PyPI).

On an apt install the real modules exist and ``ros2 launch`` runs it; here the stand-ins
record what the file asks for, so a wrong package, executable, argument or config path
fails this test.
"""

import importlib.util
import os
import sys
import types

import pytest

ROOT = os.path.join(os.path.dirname(__file__), '..', '..')


class Recorded:
    """A stand-in action or substitution that keeps its arguments."""

    def __init__(self, *args, **kwargs):
        self.args, self.kwargs = args, kwargs


def _module(name: str, **attributes) -> types.ModuleType:
    module = types.ModuleType(name)
    module.__dict__.update(attributes)
    return module


class Configuration(Recorded):
    """A stand-in LaunchConfiguration whose value comes from the fake context."""

    def perform(self, context):
        return context[self.args[0]]


@pytest.fixture
def load_launch_file(monkeypatch):
    stand_ins = {
        'launch': _module('launch', LaunchDescription=Recorded),
        'launch.actions': _module('launch.actions', DeclareLaunchArgument=Recorded,
                                  OpaqueFunction=Recorded),
        'launch.conditions': _module('launch.conditions', IfCondition=Recorded),
        'launch.substitutions': _module('launch.substitutions',
                                        LaunchConfiguration=Configuration),
        'launch_ros': _module('launch_ros'),
        'launch_ros.actions': _module('launch_ros.actions', LifecycleNode=Recorded,
                                      Node=Recorded),
        'ament_index_python.packages': _module(
            'ament_index_python.packages',
            get_package_share_directory=lambda package: os.path.abspath(ROOT)),
    }
    for name, module in stand_ins.items():
        monkeypatch.setitem(sys.modules, name, module)

    def load(name: str):
        path = os.path.join(ROOT, 'launch', name)
        spec = importlib.util.spec_from_file_location(name.replace('.', '_'), path)
        launch_file = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(launch_file)
        return launch_file
    return load


@pytest.fixture
def launch_description(load_launch_file):
    return load_launch_file('drive_bridge.launch.py').generate_launch_description()


def test_several_buses_one_node_each_and_one_aggregator(load_launch_file):
    launch_file = load_launch_file('buses.launch.py')
    actions = launch_file.generate_launch_description().args[0]
    opaque = next(action for action in actions if 'function' in action.kwargs)
    nodes = opaque.kwargs['function']({'buses': 'line1=/a.yaml; /line2=/b.yaml'})
    assert [(node.kwargs['namespace'], node.kwargs['parameters']) for node in nodes] == \
        [('line1', ['/a.yaml']), ('line2', ['/b.yaml'])]
    assert all(node.kwargs['name'] == 'drive_bridge' for node in nodes)
    aggregators = [action for action in actions
                   if action.kwargs.get('package') == 'diagnostic_aggregator']
    assert len(aggregators) == 1
    for bad in ('', 'line1', 'line1=/a.yaml;line1=/b.yaml', '=/a.yaml'):
        with pytest.raises(ValueError):
            launch_file.parse_buses(bad)


def test_launch_file_starts_the_lifecycle_node_with_the_params_file(launch_description):
    actions = launch_description.args[0]
    arguments = {action.args[0]: action.kwargs['default_value'] for action in actions
                 if 'default_value' in action.kwargs}
    assert set(arguments) == {'params_file', 'namespace', 'aggregator'}
    assert os.path.exists(arguments['params_file'])  # config/mcd.yaml in the share dir
    node = next(action for action in actions if action.kwargs.get('package') == 'drive_bridge')
    assert node.kwargs['executable'] == 'drive_bridge_node'
    assert node.kwargs['name'] == 'drive_bridge'
    assert node.kwargs['parameters'][0].args == ('params_file',)
    aggregator = next(action for action in actions
                      if action.kwargs.get('package') == 'diagnostic_aggregator')
    assert aggregator.kwargs['executable'] == 'aggregator_node'
    assert os.path.exists(aggregator.kwargs['parameters'][0])
    assert aggregator.kwargs['condition'].args[0].args == ('aggregator',)
