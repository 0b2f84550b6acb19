"""
The manual and the README against the code and themselves.

The reference covers every setting, links resolve, examples are marked for the tests that
run them, and the README stays a front page. The configuration reference itself is built
from the declarations by the docs build (docs/_ext); this checks what the build alone does
not: that its groups hold every declared setting, and that a page shows each group (the
build checks that too, with Sphinx).
"""

import os
import re

from docs_helpers import all_blocks, DOCS, markdown_reference, pages, parameter_reference, ROOT
from drive_bridge.config import model as config
from drive_bridge.devices import fc51
from drive_bridge.devices.contracts import FixedControl
from drive_bridge.devices.fc_profile_drive import FcProfileModbusDrive
from drive_bridge.protocol import fc_profile
from drive_bridge.protocol.commands import Command
from drive_bridge.sim.fc_profile_model import FcProfileModel, FcProfileSimConfig
import pytest

README_MAX_LINES = 250
LINK = re.compile(r'(?<!!)\[[^\]]*\]\(([^)\s]+)\)')
IMAGE = re.compile(r'!\[[^\]]*\]\(([^)\s]+)\)')


def test_the_reference_holds_every_declared_setting_and_nothing_else():
    names = parameter_reference().reference_names()
    declared_bus = {s.name for s in config.BUS_SETTINGS + config.NODE_SETTINGS}
    assert names['bus'] == declared_bus
    assert names['device'] == set(config.all_device_settings())


def test_every_group_of_the_reference_is_shown_on_a_page():
    shown = set()
    for page in pages():
        with open(page, encoding='utf-8') as stream:
            shown.update(markdown_reference().shown_groups(stream.read()))
    keys = {group.key for group in parameter_reference().groups()}
    assert keys - shown == set(), 'groups no page shows'
    assert shown - keys == set(), 'pages show groups that do not exist'


def test_the_reference_tables_in_the_pages_are_those_the_code_makes():
    module = markdown_reference()
    stale = [os.path.relpath(page, ROOT) for page, _ in module.stale_pages()]
    assert stale == [], f'the reference tables differ from the code: run {module.COMMAND}'


def test_no_page_shows_a_table_as_a_directive_github_cannot_render():
    tables = re.compile(r'^```\{(settings-table|families-table|protocols-table)\}', re.M)
    for page in pages():
        with open(page, encoding='utf-8') as stream:
            assert not tables.search(stream.read()), page


def test_a_stale_table_is_found_and_made_again(tmp_path):
    module = markdown_reference()
    page = tmp_path / 'page.md'
    fresh = module.regenerate('<!-- settings-table family:fc -->\n<!-- end settings-table -->')
    assert '`<name>.comms_timeout`' in fresh
    page.write_text(fresh.replace('comms_timeout', 'old_name', 1), encoding='utf-8')
    assert [path for path, _ in module.stale_pages(str(tmp_path))] == [str(page)]
    page.write_text(fresh, encoding='utf-8')
    assert module.stale_pages(str(tmp_path)) == []


def test_a_note_for_a_parameter_the_group_lacks_is_refused():
    module = markdown_reference()
    with pytest.raises(module.TableError, match='notes for nothing_here'):
        module.regenerate('<!-- settings-table family:fc\nnothing_here: x\n-->\n'
                          '<!-- end settings-table -->')


def headings(path: str) -> set:
    """Return the anchors of a Markdown file's headings, as GitHub and MyST make them."""
    anchors = set()
    with open(path, encoding='utf-8') as stream:
        text = re.sub(r'```.*?```', '', stream.read(), flags=re.DOTALL)
    for title in re.findall(r'^#{1,6} (.+)$', text, re.MULTILINE):
        slug = re.sub(r'[^\w\- ]', '', title.strip().lower()).replace(' ', '-')
        anchors.add(slug)
    return anchors


def local_links(page: str) -> list:
    with open(page, encoding='utf-8') as stream:
        text = re.sub(r'```.*?```', '', stream.read(), flags=re.DOTALL)
    targets = LINK.findall(text) + IMAGE.findall(text)
    return [target for target in targets if '://' not in target and
            not target.startswith('mailto:')]


@pytest.mark.parametrize('page', pages(), ids=lambda page: os.path.relpath(page, ROOT))
def test_every_link_names_a_file_and_heading_that_exist(page):
    for target in local_links(page):
        path, _, anchor = target.partition('#')
        path = os.path.normpath(os.path.join(os.path.dirname(page), path)) if path else page
        assert os.path.exists(path), f'{os.path.relpath(page, ROOT)}: {target}: no such file'
        if anchor and path.endswith('.md'):
            assert anchor in headings(path), \
                f'{os.path.relpath(page, ROOT)}: {target}: no such heading'


def test_the_readme_is_a_front_page_that_links_into_the_manual():
    with open(os.path.join(ROOT, 'README.md'), encoding='utf-8') as stream:
        text = stream.read()
    assert len(text.splitlines()) <= README_MAX_LINES
    linked = {os.path.normpath(target.partition('#')[0]) for target in
              local_links(os.path.join(ROOT, 'README.md'))}
    for page in ('quickstart', 'install', 'configuration', 'safety', 'contributing'):
        assert os.path.join('docs', f'{page}.md') in linked, page


def test_every_tool_example_is_marked_for_a_test_that_runs_it():
    tools = ('drive-bridge ', 'drive_bridge_sim ', 'drive_bridge_record ', 'drive_bridge_plot ',
             'drive_bridge_ctl ')
    unmarked = [block.where for block in all_blocks()
                if any(command.startswith(tools) for command, _ in block.commands())
                and not block.marker]
    assert unmarked == []


def test_every_page_is_in_the_table_of_contents():
    listed = set()
    for page in pages():
        with open(page, encoding='utf-8') as stream:
            text = stream.read()
        for toctree in re.findall(r'```\{toctree\}\n(.*?)```', text, re.DOTALL):
            listed.update(row.strip() for row in toctree.splitlines()
                          if row.strip() and not row.startswith(':'))
    names = {os.path.basename(page)[:-3] for page in pages() if page.startswith(DOCS)}
    assert names - listed == {'index'}


def test_troubleshooting_says_what_a_drive_started_at_a_0_percent_reference_reads():
    # The page said such a drive stays ready; the manual (004 5.6.4, bit 11 Running: "a start
    # signal or ... output frequency higher than 0 Hz") and the simulated FC 51 say running.
    model = FcProfileModel(FcProfileSimConfig(), now_s=0.0)
    model.write_control(fc_profile.START_WORD, 0, 0.0)  # start, reference 0 %
    model.advance(1.0)
    reading = FcProfileModbusDrive(fc51.DATA, 'fc51').reading(
        model.status_word(), model.actual_word(), FixedControl(Command.START, 0))
    assert (reading.state, reading.speed_feedback_pct) == ('running', 0.0)
    with open(os.path.join(DOCS, 'troubleshooting.md'), encoding='utf-8') as stream:
        rows = [line for line in stream if line.startswith('| FC') and '0 %' in line]
    assert rows, 'troubleshooting has no row for a drive started at a 0 % reference'
    for row in rows:
        symptom = row.split(' | ')[0]
        assert f'`{reading.state}`' in symptom and '`ready`' not in symptom, row


def test_the_readme_and_every_device_page_point_at_the_one_write_rule():
    # Issue 26: the README's FC 51 and VLT sections stated their own rule ("Nothing, until a
    # command arrives"), which the code did not follow. The rule is stated once (safety.md);
    # the README and the device pages link to it, or to a page that carries it out.
    rule = 'safety.md#what-is-written-and-when'
    with open(os.path.join(DOCS, 'devices.md'), encoding='utf-8') as stream:
        toctree = stream.read().split('```{toctree}')[1].split('```')[0]
    families = [line.strip() for line in toctree.splitlines()[1:] if line.strip() and
                not line.startswith(':')]
    assert families == ['mcd', 'lvsg', 'fc51', 'vlt', 'fc_protocol']
    with open(os.path.join(ROOT, 'README.md'), encoding='utf-8') as stream:
        texts = {'README.md': stream.read()}
    for family in families:
        with open(os.path.join(DOCS, f'{family}.md'), encoding='utf-8') as stream:
            texts[family] = stream.read()
    carried_out = {'fc51': 'fc51.md#what-the-bridge-writes'}
    for name, text in texts.items():
        assert rule in text or any(link in text for link in carried_out.values()), name
        assert 'Nothing, until a command arrives' not in text, name
