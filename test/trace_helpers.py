"""Reading wire traces back in tests: tshark's fields (skipped without tshark), records."""

import shutil
import subprocess
from typing import List

import pytest

TSHARK = shutil.which('tshark')
needs_tshark = pytest.mark.skipif(
    TSHARK is None, reason='tshark is not installed: apt-get install tshark (.ci/run does)')


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

    def rows(self):
        """Return (direction, hex bytes, outcome, unit) of each record."""
        return [('RX' if r.inbound else 'TX', r.data.hex(), r.outcome, r.unit)
                for r in self.records]
