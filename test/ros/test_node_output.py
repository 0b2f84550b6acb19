"""The node's log as the tests read it: every line whole while the node writes."""

import subprocess
import sys
import tempfile

from ros_helpers import node_output

LINES = 3000


def test_reading_the_log_while_the_node_writes_loses_nothing():
    # The node writes through descriptors that share the log file's offset with the test's
    # file object: a seek(0) there made the node overwrite the log's start (before the fix
    # this test read 2062-2188 lines of 3000, three runs of three).
    log = tempfile.NamedTemporaryFile('w+', suffix='.log')
    writer = subprocess.Popen(
        [sys.executable, '-c',
         f"for i in range({LINES}): print(f'line {{i}} is a pty', flush=True)"],
        stdout=log, stderr=log, text=True)
    writer.log = log
    while writer.poll() is None:
        node_output(writer)
    lines = node_output(writer).splitlines()
    wrong = [line for line in lines if not line.startswith('line ')]
    assert lines == [f'line {i} is a pty' for i in range(LINES)], \
        f'{len(lines)} lines of {LINES}, {len(wrong)} broken: {wrong[:3]}'
