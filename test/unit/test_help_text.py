"""
Every terminal command's ``--help`` is plain text: no Sphinx or MyST markup.

The descriptions come from docstrings that the docs build also reads (``:data:`X```,
``` ``literal`` ```); :func:`drive_bridge.console.plain_text` strips the markup. Each parser
and every subcommand's parser is formatted here; argparse's own braces (``{N,E,O}``, the
choices) are not markup and stay.
"""

import argparse
import os
import re
import subprocess
import sys

from drive_bridge.console import plain_text
from drive_bridge.sim import cli as sim_cli
from drive_bridge.tools import cli as tools_cli, plot_recording
import pytest

MARKUP = re.compile(r'``|:[a-z]+(:[a-z]+)?:`|\{[a-z-]+\}`')


def all_helps(parser: argparse.ArgumentParser, prog: str = ''):
    """Yield (command line, help text) of ``parser`` and of every subcommand under it."""
    yield prog or parser.prog, parser.format_help()
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from all_helps(sub, f'{prog or parser.prog} {name}')


def markup_in(parser: argparse.ArgumentParser) -> list:
    """Return each (command, line) of a help text that holds markup."""
    return [(command, line) for command, text in all_helps(parser)
            for line in text.splitlines() if MARKUP.search(line)]


def test_plain_text_strips_roles_and_literals():
    text = ('within 10 s (:data:`TEARDOWN_LIMIT_S`), see :class:`~drive_bridge.x.Session`, '
            ':py:func:`a.b`, {ref}`Safety <safety>` and ``drive_bridge_ctl echo ... | head``')
    assert plain_text(text) == ('within 10 s (TEARDOWN_LIMIT_S), see Session, a.b, Safety '
                                'and drive_bridge_ctl echo ... | head')


@pytest.mark.parametrize('build', [tools_cli.build_parser, sim_cli.build_parser,
                                   plot_recording.build_parser],
                         ids=['drive-bridge', 'drive_bridge_sim', 'drive_bridge_plot'])
def test_help_of_the_commands_without_ros_is_plain_text(build):
    assert markup_in(build()) == []


def test_help_of_the_ros_commands_is_plain_text():
    pytest.importorskip('rclpy')
    from drive_bridge.ros.ctl import cli as ctl
    from drive_bridge.ros.record import cli as record
    assert markup_in(ctl._parser()) == []
    assert markup_in(record.build_parser()) == []


def test_drive_bridge_ctl_help_as_printed_is_plain_text():
    pytest.importorskip('rclpy')
    result = subprocess.run([sys.executable, '-m', 'drive_bridge.ros.ctl.cli', '--help'],
                            capture_output=True, text=True, timeout=120,
                            env=dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path)))
    assert result.returncode == 0, result.stderr
    assert 'TEARDOWN_LIMIT_S' in result.stdout  # the description is there, as text
    assert [line for line in result.stdout.splitlines() if MARKUP.search(line)] == []
