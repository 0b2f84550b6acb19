"""
The reference tables of the manual as Markdown, written into the pages themselves.

A page holds each table between two HTML comments, which GitHub and Sphinx both hide; the
opening one names the table and, for ``settings-table GROUP``, holds the notes (YAML: a
parameter of the group -> a further note in Markdown)::

    <!-- settings-table bus
    port: |
      A local serial device, or a `socket://host:port` URL.
    -->
    | parameter | type | default | allowed | runtime | meaning |
    ...
    <!-- end settings-table -->

The tables come from the code (:mod:`parameter_reference`), so they are committed generated
text: ``python docs/_ext/markdown_reference.py`` rewrites every page's tables (run it after
changing a setting, a family or a protocol), ``--check`` says which pages are stale. The
tests and the docs build (:mod:`drive_bridge_docs`) check that no page is stale and that a
page shows every group. No Sphinx here.
"""

import os
import re
import sys
from typing import Any, Dict, Iterable, List, Sequence, Tuple

HERE = os.path.dirname(os.path.abspath(__file__))
DOCS = os.path.dirname(HERE)
ROOT = os.path.dirname(DOCS)
if __name__ == '__main__':  # run as a script: the package beside docs/, parameter_reference
    sys.path[:0] = [ROOT, HERE]

import parameter_reference as reference  # noqa: E402 - after the path is set
import yaml  # noqa: E402

COMMAND = 'python docs/_ext/markdown_reference.py'
KINDS = ('settings-table', 'families-table', 'protocols-table')
BLOCK = re.compile(r'^<!-- (?P<kind>[a-z-]+-table)(?: (?!-->)(?P<key>\S+))? ?'
                   r'(?P<notes>\n.*?)?-->\n(?P<body>.*?)^<!-- end (?P=kind) -->$',
                   re.MULTILINE | re.DOTALL)
SETTINGS_HEADERS = ('parameter', 'type', 'default', 'allowed', 'runtime', 'meaning')
PLAIN_SPECIALS = re.compile(r'([\\`*<>\[\]|~])')


class TableError(Exception):
    """A table of a page that cannot be made (unknown group, notes that do not fit)."""


def plain(text: str) -> str:
    """Return plain text as Markdown that shows it as it is (in a table cell)."""
    return PLAIN_SPECIALS.sub(r'\\\1', text)


def code(text: str) -> str:
    """Return ``text`` as inline code in a table cell ('' stays empty)."""
    return f'`{text.replace("|", chr(92) + "|")}`' if text else ''


def codes(text: str) -> str:
    """Return comma-separated values, each as code."""
    return ', '.join(code(value) for value in text.split(', ') if value)


def cell_markdown(text: str) -> str:
    """Return a Markdown note as one table cell: its lines joined, its pipes escaped."""
    joined = ' '.join(line.strip() for line in text.strip().splitlines() if line.strip())
    return re.sub(r'(?<!\\)\|', r'\\|', joined)


def table(headers: Sequence[str], rows: Iterable[Sequence[str]]) -> str:
    """Return a Markdown table."""
    lines = ['| ' + ' | '.join(headers) + ' |', '|' + ' --- |' * len(headers)]
    lines += ['| ' + ' | '.join(row) + ' |' for row in rows]
    return '\n'.join(lines) + '\n'


def parse_notes(key: str, text: str) -> Dict[str, Any]:
    """Return the notes of a settings table (YAML); raise TableError if they do not fit."""
    try:
        notes = yaml.safe_load(text or '') or {}
    except yaml.YAMLError as error:
        raise TableError(f'settings-table {key}: the notes are not YAML: {error}') from None
    if not isinstance(notes, dict):
        raise TableError(f'settings-table {key}: give the notes as name: text')
    return notes


def settings_table(key: str, notes: Dict[str, Any]) -> str:
    """Return the table of settings group ``key``, each with its note."""
    try:
        group = reference.group(key)
    except KeyError as error:
        raise TableError(str(error.args[0])) from None
    names = {setting.name for setting in group.settings}
    unknown = sorted(set(notes) - names)
    if unknown:
        raise TableError(f'settings-table {key}: notes for {", ".join(unknown)}, which the '
                         f'group does not have (it has {", ".join(sorted(names))})')
    rows = []
    for setting in group.settings:
        meaning = plain(setting.description)
        if notes.get(setting.name):
            meaning = meaning.rstrip('.') + '. ' + cell_markdown(str(notes[setting.name]))
        default = reference.default_of(setting)
        allowed = reference.allowed_of(setting)
        rows.append((code(group.prefix + setting.name), reference.type_of(setting),
                     code(default) if setting.default is not None else 'required',
                     codes(allowed) if setting.choices else plain(allowed),
                     'yes' if setting.runtime else '', meaning))
    title = f'**{group.title}**\n\n' if ':' in key else ''
    return title + table(SETTINGS_HEADERS, rows)


def families_table() -> str:
    """Return the table of the device families."""
    return table(('family', 'devices', 'model', 'address', 'protocol', 'simulator models'),
                 [(code(name), plain(text), codes(models), addresses, codes(protocols),
                   codes(simulated))
                  for name, text, models, addresses, protocols, simulated
                  in reference.family_rows()])


def protocols_table() -> str:
    """Return the table of the bus protocols."""
    return table(('protocol', 'what it is', 'link', 'framing', 'families', 'own settings'),
                 [(code(name), plain(text), plain(link), plain(framing), codes(families),
                   codes(settings))
                  for name, text, link, framing, families, settings
                  in reference.protocol_rows()])


def render(kind: str, key: str, notes_text: str) -> str:
    """Return the body of one table."""
    if kind == 'settings-table':
        if not key:
            raise TableError('settings-table needs a group: <!-- settings-table GROUP')
        return settings_table(key, parse_notes(key, notes_text))
    if kind == 'families-table':
        return families_table()
    if kind == 'protocols-table':
        return protocols_table()
    raise TableError(f'unknown table {kind!r}: there are {", ".join(KINDS)}')


def regenerate(text: str, where: str = '') -> str:
    """Return a page's text with every table made again from the code."""
    def one(match: 're.Match[str]') -> str:
        try:
            body = render(match['kind'], match['key'] or '', match['notes'] or '')
        except TableError as error:
            raise TableError(f'{where}: {error}') from None
        head = match.group(0)[:match.start('body') - match.start(0)]
        return f'{head}{body}<!-- end {match["kind"]} -->'
    return BLOCK.sub(one, text)


def shown_groups(text: str) -> List[str]:
    """Return the settings groups a page's text shows."""
    return [match['key'] for match in BLOCK.finditer(text)
            if match['kind'] == 'settings-table' and match['key']]


def pages(docs: str = DOCS) -> List[str]:
    """Return the manual's pages."""
    return [os.path.join(docs, name) for name in sorted(os.listdir(docs))
            if name.endswith('.md')]


def stale_pages(docs: str = DOCS) -> List[Tuple[str, str]]:
    """Return (page, the text it should have) of each page whose tables are not current."""
    stale = []
    for page in pages(docs):
        with open(page, encoding='utf-8') as stream:
            text = stream.read()
        fresh = regenerate(text, os.path.relpath(page, ROOT))
        if fresh != text:
            stale.append((page, fresh))
    return stale


def unshown_groups(docs: str = DOCS) -> List[str]:
    """Return the settings groups that no page shows."""
    shown = set()
    for page in pages(docs):
        with open(page, encoding='utf-8') as stream:
            shown.update(shown_groups(stream.read()))
    return [group.key for group in reference.groups() if group.key not in shown]


def main(argv: List[str]) -> int:
    """Rewrite the stale pages (``--check``: only name them, exit status 1 if any)."""
    check = '--check' in argv
    try:
        stale = stale_pages()
    except TableError as error:
        print(f'markdown_reference: {error}', file=sys.stderr)
        return 2
    for page, fresh in stale:
        if not check:
            with open(page, 'w', encoding='utf-8') as stream:
                stream.write(fresh)
        print(f'{"stale" if check else "rewritten"}: {os.path.relpath(page, ROOT)}')
    missing = unshown_groups()
    if missing:
        print(f'no page shows the settings groups {", ".join(missing)}: add '
              f'"<!-- settings-table GROUP -->" ... "<!-- end settings-table -->" to a page',
              file=sys.stderr)
    return 1 if (check and stale) or missing else 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
