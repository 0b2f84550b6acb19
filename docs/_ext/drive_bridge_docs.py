"""
Sphinx extension of the drive_bridge manual: reference tables built from the code.

Directives:

- ``settings-table GROUP``: the parameters of one group of :mod:`parameter_reference`
  (name, type, default, allowed values, whether ``ros2 param set`` may change it, and the
  description the code declares). Its content, if any, is YAML mapping a parameter of the
  group to a further note in Markdown; a note for a parameter the group does not have is an
  error, so the notes cannot outlive the code either.
- ``families-table`` and ``protocols-table``: the device families and bus protocols, from
  their registries.

Every group must be rendered somewhere: a group nobody shows is a warning (an error with
``-W``). Without sphinx-argparse (a rosdoc2 machine may not have it) an ``argparse``
directive that prints the command's ``--help`` stands in for its own.
"""

import importlib
from typing import Any, Dict, Iterable, List, Sequence

from docutils import nodes
from docutils.statemachine import StringList
import parameter_reference as reference
from sphinx.application import Sphinx
from sphinx.util import logging
from sphinx.util.docutils import SphinxDirective
import yaml

LOGGER = logging.getLogger(__name__)
SETTINGS_HEADERS = ('parameter', 'type', 'default', 'allowed', 'runtime', 'meaning')
SETTINGS_WIDTHS = (18, 8, 10, 14, 7, 43)


def _cell(*children: nodes.Node) -> nodes.entry:
    entry = nodes.entry()
    entry.extend(children)
    return entry


def _text(text: str) -> nodes.paragraph:
    return nodes.paragraph(text=text)


def _code(text: str) -> nodes.paragraph:
    paragraph = nodes.paragraph()
    if text:
        paragraph += nodes.literal(text=text)
    return paragraph


def _codes(text: str) -> nodes.paragraph:
    """Return a paragraph of comma-separated values, each as code."""
    paragraph = nodes.paragraph()
    for index, value in enumerate(v for v in text.split(', ') if v):
        if index:
            paragraph += nodes.Text(', ')
        paragraph += nodes.literal(text=value)
    return paragraph


def make_table(headers: Sequence[str], widths: Sequence[int],
               rows: Iterable[Sequence[nodes.entry]]) -> nodes.table:
    """Return a docutils table with ``headers`` and rows of ready-made cells."""
    table = nodes.table(classes=['drive-bridge-reference'])
    group = nodes.tgroup(cols=len(headers))
    table += group
    group.extend(nodes.colspec(colwidth=width) for width in widths)
    head = nodes.thead()
    head += nodes.row('', *(_cell(_text(header)) for header in headers))
    group += head
    body = nodes.tbody()
    body.extend(nodes.row('', *cells) for cells in rows)
    group += body
    return table


class SettingsTable(SphinxDirective):
    """``settings-table GROUP``: one group of parameters, with optional notes (YAML)."""

    required_arguments = 1
    has_content = True

    def run(self) -> List[nodes.Node]:
        try:
            group = reference.group(self.arguments[0])
        except KeyError as error:
            raise self.error(str(error.args[0])) from None
        notes = self._notes(group)
        rows = [self._row(group, setting, notes.get(setting.name))
                for setting in group.settings]
        shown = self.env.__dict__.setdefault('drive_bridge_groups', {})
        shown.setdefault(group.key, set()).add(self.env.docname)
        table = make_table(SETTINGS_HEADERS, SETTINGS_WIDTHS, rows)
        table.insert(0, nodes.title(text=group.title))
        table['ids'].append(nodes.make_id(f'parameters-{group.key}'))
        return [table]

    def _notes(self, group: reference.Group) -> Dict[str, Any]:
        try:
            notes = yaml.safe_load('\n'.join(self.content)) or {}
        except yaml.YAMLError as error:
            raise self.error(f'settings-table {group.key}: the notes are not YAML: {error}')
        if not isinstance(notes, dict):
            raise self.error(f'settings-table {group.key}: give the notes as name: text')
        names = {setting.name for setting in group.settings}
        unknown = sorted(set(notes) - names)
        if unknown:
            raise self.error(f'settings-table {group.key}: notes for {", ".join(unknown)}, '
                             f'which the group does not have (it has {", ".join(sorted(names))})')
        return notes

    def _row(self, group: reference.Group, setting, note) -> List[nodes.entry]:
        name = _code(group.prefix + setting.name)
        name['ids'].append(nodes.make_id(f'{group.key}-{setting.name}'))
        meaning = _cell(_text(setting.description))
        if note:
            self.state.nested_parse(StringList(str(note).splitlines(), self.get_source_info()[0]),
                                    self.content_offset, meaning)
        default = reference.default_of(setting)
        return [_cell(name), _cell(_text(reference.type_of(setting))),
                _cell(_code(default) if setting.default is not None else _text('required')),
                _cell(_codes(reference.allowed_of(setting)) if setting.choices
                      else _text(reference.allowed_of(setting))),
                _cell(_text('yes' if setting.runtime else '')), meaning]


class FamiliesTable(SphinxDirective):
    """``families-table``: the device families of the registry."""

    def run(self) -> List[nodes.Node]:
        rows = [[_cell(_code(name)), _cell(_text(text)), _cell(_codes(models)),
                 _cell(_text(addresses)), _cell(_codes(protocols)), _cell(_codes(simulated))]
                for name, text, models, addresses, protocols, simulated
                in reference.family_rows()]
        return [make_table(('family', 'devices', 'model', 'address', 'protocol',
                            'simulator models'), (8, 30, 16, 8, 20, 18), rows)]


class ProtocolsTable(SphinxDirective):
    """``protocols-table``: the bus protocols of the protocol table."""

    def run(self) -> List[nodes.Node]:
        rows = [[_cell(_code(name)), _cell(_text(text)), _cell(_text(link)),
                 _cell(_text(framing)), _cell(_codes(families)), _cell(_codes(settings))]
                for name, text, link, framing, families, settings
                in reference.protocol_rows()]
        return [make_table(('protocol', 'what it is', 'link', 'framing', 'families',
                            'own settings'), (12, 30, 6, 22, 14, 16), rows)]


class HelpText(SphinxDirective):
    """Stand-in for sphinx-argparse's ``argparse``: the parser's ``--help`` as text."""

    has_content = True
    option_spec = {'module': str, 'func': str, 'prog': str}

    def run(self) -> List[nodes.Node]:
        parser = getattr(importlib.import_module(self.options['module']),
                         self.options['func'])()
        if 'prog' in self.options:
            parser.prog = self.options['prog']
        return [nodes.literal_block(text=parser.format_help())]


def check_every_group_shown(app: Sphinx, env) -> None:
    """Warn about a group of parameters no page renders (its parameters would be missing)."""
    shown = getattr(env, 'drive_bridge_groups', {})
    for group in reference.groups():
        if not shown.get(group.key):
            LOGGER.warning(f'drive_bridge_docs: no page shows the parameters of group '
                           f'{group.key!r} ({", ".join(s.name for s in group.settings)}): add '
                           f'a "settings-table {group.key}" directive')


def forget_document(app: Sphinx, env, docname: str) -> None:
    """Forget which groups ``docname`` showed (it is read again)."""
    for pages in getattr(env, 'drive_bridge_groups', {}).values():
        pages.discard(docname)


def merge_shown(app: Sphinx, env, docnames, other) -> None:
    """Merge what a parallel reader saw."""
    shown = env.__dict__.setdefault('drive_bridge_groups', {})
    for key, pages in getattr(other, 'drive_bridge_groups', {}).items():
        shown.setdefault(key, set()).update(pages)


def add_help_stand_in(app: Sphinx, config) -> None:
    """Register the ``argparse`` stand-in when sphinx-argparse is not loaded."""
    if 'sphinxarg.ext' not in app.extensions:
        LOGGER.info('drive_bridge_docs: sphinx-argparse is not loaded: the command '
                    'references show --help')
        app.add_directive('argparse', HelpText)


def setup(app: Sphinx) -> Dict[str, Any]:
    """Register the directives and the check."""
    app.add_directive('settings-table', SettingsTable)
    app.add_directive('families-table', FamiliesTable)
    app.add_directive('protocols-table', ProtocolsTable)
    app.connect('config-inited', add_help_stand_in)
    app.connect('env-check-consistency', check_every_group_shown)
    app.connect('env-purge-doc', forget_document)
    app.connect('env-merge-info', merge_shown)
    return {'version': '1', 'parallel_read_safe': True, 'parallel_write_safe': True}
