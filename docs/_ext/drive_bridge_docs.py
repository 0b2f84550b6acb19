"""
Sphinx extension of the drive_bridge manual: the reference tables must be current.

The reference tables (settings of each group, device families, bus protocols) are Markdown
in the pages, made from the code by :mod:`markdown_reference` (so that GitHub shows them
too). The build checks what the tests check: a page whose tables differ from the code, or
a group of settings that no page shows, is a warning (an error with ``-W``) that names the
command that rewrites them. Without sphinx-argparse (a rosdoc2 machine may not have it) an
``argparse`` directive that prints the command's ``--help`` stands in for its own.
"""

import importlib
import os
from typing import Any, Dict, List

from docutils import nodes
import markdown_reference
from sphinx.application import Sphinx
from sphinx.util import logging
from sphinx.util.docutils import SphinxDirective

LOGGER = logging.getLogger(__name__)


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


def check_reference_tables(app: Sphinx, env) -> None:
    """Warn about stale reference tables and settings groups no page shows."""
    try:
        stale = markdown_reference.stale_pages(app.srcdir)
    except markdown_reference.TableError as error:
        LOGGER.warning(f'drive_bridge_docs: {error}')
        return
    for page, _ in stale:
        LOGGER.warning(f'drive_bridge_docs: the reference tables of {os.path.basename(page)} '
                       f'differ from the code: run {markdown_reference.COMMAND}')
    for key in markdown_reference.unshown_groups(app.srcdir):
        LOGGER.warning(f'drive_bridge_docs: no page shows the parameters of group {key!r}: '
                       f'add "<!-- settings-table {key} -->" and "<!-- end settings-table -->" '
                       f'to a page, then run {markdown_reference.COMMAND}')


def add_help_stand_in(app: Sphinx, config) -> None:
    """Register the ``argparse`` stand-in when sphinx-argparse is not loaded."""
    if 'sphinxarg.ext' not in app.extensions:
        LOGGER.info('drive_bridge_docs: sphinx-argparse is not loaded: the command '
                    'references show --help')
        app.add_directive('argparse', HelpText)


def setup(app: Sphinx) -> Dict[str, Any]:
    """Register the stand-in and the check."""
    app.connect('config-inited', add_help_stand_in)
    app.connect('env-check-consistency', check_reference_tables)
    return {'version': '2', 'parallel_read_safe': True, 'parallel_write_safe': True}
