"""
The code blocks of the manual (docs/*.md) and the README, with the test markers above them.

A marker is an HTML comment on the line just above a fenced block, invisible on the page:
``<!-- test: run -->``. The tests that run the docs' examples read the blocks from here; see
docs/contributing.md ("The docs") for the markers.
"""

from dataclasses import dataclass
import importlib
import os
import re
import shlex
import sys
from types import ModuleType
from typing import List, Tuple

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DOCS = os.path.join(ROOT, 'docs')
MARKER = re.compile(r'<!-- test: (.*?) -->')
FENCE = re.compile(r'^(`{3,})(\S*)')
OUTPUT = '#   '  # a line of expected output under a command


@dataclass
class Block:
    """One fenced code block: its page, line, language, marker ('' if none) and lines."""

    page: str
    line: int
    language: str
    marker: str
    lines: List[str]

    @property
    def where(self) -> str:
        return f'{os.path.relpath(self.page, ROOT)}:{self.line}'

    def commands(self) -> List[Tuple[str, List[str]]]:
        """Return (command line, expected output lines) of a shell block."""
        commands: List[Tuple[str, List[str]]] = []
        pending = ''
        for row in self.lines:
            if row.startswith(OUTPUT) and commands:
                commands[-1][1].append(row[len(OUTPUT):])
            elif row.strip() and not row.lstrip().startswith('#'):
                pending += row[:-1] + ' ' if row.endswith('\\') else row
                if not row.endswith('\\'):
                    commands.append((pending, []))
                    pending = ''
        return commands


def pages() -> List[str]:
    """Return the manual's pages and the README."""
    names = sorted(name for name in os.listdir(DOCS) if name.endswith('.md'))
    return [os.path.join(DOCS, name) for name in names] + [os.path.join(ROOT, 'README.md')]


def blocks(page: str) -> List[Block]:
    """Return the fenced code blocks of ``page``, each with the marker just above it."""
    with open(page, encoding='utf-8') as stream:
        rows = stream.read().splitlines()
    found, index = [], 0
    while index < len(rows):
        fence = FENCE.match(rows[index])
        if not fence:
            index += 1
            continue
        above = rows[index - 1] if index else ''
        marker = MARKER.fullmatch(above.strip())
        end = index + 1
        while end < len(rows) and not rows[end].startswith(fence.group(1)):
            end += 1
        found.append(Block(page, index + 1, fence.group(2), marker.group(1) if marker else '',
                           rows[index + 1:end]))
        index = end + 1
    return found


def all_blocks() -> List[Block]:
    """Return every code block of every page."""
    return [block for page in pages() for block in blocks(page)]


def words(command: str) -> List[str]:
    """Split a command line as the shell would (a trailing comment dropped)."""
    return shlex.split(command, comments=True)


def parameter_reference() -> ModuleType:
    """Return docs/_ext/parameter_reference, the configuration reference as data."""
    return _extension_module('parameter_reference')


def markdown_reference() -> ModuleType:
    """Return docs/_ext/markdown_reference, which writes the reference tables into pages."""
    return _extension_module('markdown_reference')


def _extension_module(name: str) -> ModuleType:
    extensions = os.path.join(DOCS, '_ext')
    if extensions not in sys.path:
        sys.path.insert(0, extensions)
    return importlib.import_module(name)
