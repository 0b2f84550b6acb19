"""Reading wire traces back in tests: tshark (skipped without it), the Lua dissectors, ptys."""

import shutil
import subprocess
from typing import List

from pty_witness import run_unless_a_pty_lagged
import pytest

TSHARK = shutil.which('tshark')
needs_tshark = pytest.mark.skipif(
    TSHARK is None, reason='tshark is not installed: apt-get install tshark (.ci/run does)')

PTY_MARGIN_S = 0.4  # a pty lag this long could turn a reply into a timeout


def on_a_pty(test, tmp_path, margin_s: float = PTY_MARGIN_S) -> None:
    """Run ``test(directory)``, again only if it failed while a pty lagged (a new directory)."""
    runs = iter(range(1, 4))
    run_unless_a_pty_lagged(lambda: test(_fresh(tmp_path / f'run{next(runs)}')), margin_s)


def _fresh(directory):
    directory.mkdir()
    return directory


def tshark_fields(path, *fields, display_filter: str = '') -> List[List[str]]:
    """Return one row of ``fields`` per packet of the trace at ``path``, as tshark decodes it."""
    command = [TSHARK, '-r', str(path), '-T', 'fields', '-E', 'separator=|']
    if display_filter:
        command += ['-Y', display_filter]
    for field in fields:
        command += ['-e', field]
    done = subprocess.run(command, capture_output=True, text=True, timeout=120, check=True)
    assert 'error' not in done.stderr.lower(), done.stderr
    return [line.split('|') for line in done.stdout.splitlines()]


def tshark(path, script, fields, *options, display_filter=''):
    """
    Return the rows of ``fields`` (a dict per frame).

    Fail on any message on stderr (a syntax error in a script leaves the exit status 0) and
    on a Lua error while a frame was dissected (an expert info in the frame).
    """
    command = [TSHARK, '-n', '-X', f'lua_script:{script}', '-r', str(path), *options,
               '-T', 'fields', '-E', 'separator=/t', '-E', 'occurrence=a',
               '-E', 'aggregator=;']
    if display_filter:
        command += ['-Y', display_filter]
    for field in [*fields, '_ws.expert.message']:
        command += ['-e', field]
    done = subprocess.run(command, capture_output=True, text=True, timeout=120)
    problems = [line for line in done.stderr.splitlines()
                if 'running as user' not in line.lower()]
    assert done.returncode == 0 and not problems, done.stderr
    rows = [line.split('\t') for line in done.stdout.splitlines()]
    lua_errors = [row[-1] for row in rows if 'Lua Error' in row[-1]]
    assert lua_errors == [], lua_errors[:3]
    return [dict(zip(fields, row)) for row in rows]


def outcomes(rows, column: int = -1) -> List[str]:
    """Return the ``outcome=`` word of each row's comment column ('' where none)."""
    words = []
    for row in rows:
        found = [word[len('outcome='):] for word in row[column].split()
                 if word.startswith('outcome=')]
        words.append(found[0] if found else '')
    return words


class RecordingTrace:
    """A WireTrace stand-in that keeps the records it is given."""

    def __init__(self):
        self.records = []
        self.enabled = True
        self.failures = []

    def fail(self, error) -> None:
        self.enabled = False
        self.failures.append(error)

    def write(self, records) -> None:
        self.records.extend(records)

    def close(self) -> None:
        pass

    def drain(self) -> bool:
        return True

    def rows(self):
        """Return (direction, hex bytes, outcome, unit) of each record."""
        return [('RX' if r.inbound else 'TX', r.data.hex(), r.outcome, r.unit)
                for r in self.records]
