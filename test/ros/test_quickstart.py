"""
The quick start (docs/quickstart.md) as written.

Simulator, configuration, drive-bridge, the node and an rclpy client, each block as the
page's marker says (docs/contributing.md). One change to the page's commands: the
simulator's link ``/tmp/drive_bridge_line`` becomes a path of this test's own, so that test
runs can share a machine. The commands run in a scratch directory with the checkout's
``config/`` beside them, in this venv (the page's environment block is checked against the
test's environment, not run: the venv is this one).
"""

import os
import re
import shlex
import subprocess
import sys
import time
from typing import Dict, List

from docs_helpers import Block, blocks, DOCS, ROOT
import pytest
from ros_helpers import node_output

PAGE = os.path.join(DOCS, 'quickstart.md')
LINK = '/tmp/drive_bridge_line'
BACKGROUND = re.compile(r'background until "(.+)"')
START_S = 60.0
RUN_S = 120.0


def normalized(text: str) -> str:
    """Return ``text`` with pty numbers left out (they change from run to run)."""
    return re.sub(r'/dev/pts/\d+', '/dev/pts/N', text)


class QuickStart:
    """The page's terminals: a scratch directory, an environment and background processes."""

    def __init__(self, workdir):
        self.workdir = workdir
        self.link = str(workdir / 'drive_bridge_line')
        bin_dir = os.path.dirname(sys.executable)
        self.env = dict(os.environ, VIRTUAL_ENV=sys.prefix,
                        PATH=bin_dir + os.pathsep + os.environ.get('PATH', ''))
        self.background: List[subprocess.Popen] = []
        os.symlink(os.path.join(ROOT, 'config'), workdir / 'config')

    def here(self, text: str) -> str:
        return text.replace(LINK, self.link)

    def environment(self, block: Block) -> None:
        for command, _ in block.commands():
            words = shlex.split(command)
            if words[0] == 'export':
                for assignment in words[1:]:
                    name, _, value = assignment.partition('=')
                    value = value.replace('$VIRTUAL_ENV', sys.prefix)
                    assert os.environ.get(name, value) == value, f'{name}: the test runs ' \
                        f'with {os.environ[name]!r}, the page says {value!r}'
                    self.env[name] = value
            elif words[0] == '.':
                assert words[1] == '.venv/bin/activate', command
            else:
                assert os.path.exists(os.path.join(ROOT, words[0])), command

    def start(self, block: Block, ready: str) -> None:
        for command, expected in block.commands():
            log = open(self.workdir / f'background_{len(self.background)}.log', 'w+')
            process = subprocess.Popen(['bash', '-c', 'exec ' + self.here(command)],
                                       cwd=self.workdir, env=self.env, stdout=log,
                                       stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
            process.log = log
            self.background.append(process)
            deadline = time.monotonic() + START_S
            while ready not in node_output(process):
                assert process.poll() is None, f'{command} ended:\n{node_output(process)}'
                assert time.monotonic() < deadline, f'{command}:\n{node_output(process)}'
                time.sleep(0.05)
            self.expect(command, expected, node_output(process))

    def run(self, block: Block) -> None:
        for command, expected in block.commands():
            done = subprocess.run(['bash', '-c', self.here(command)], cwd=self.workdir,
                                  env=self.env, stdout=subprocess.PIPE,
                                  stderr=subprocess.STDOUT, text=True, timeout=RUN_S)
            assert done.returncode == 0, f'{command}:\n{done.stdout}\n{self.logs()}'
            self.expect(command, expected, done.stdout)

    def write(self, block: Block, name: str) -> None:
        (self.workdir / name).write_text('\n'.join(block.lines) + '\n')

    def lines_of(self, block: Block, name: str) -> None:
        written = {row.split(' #')[0].rstrip() for row in
                   (self.workdir / name).read_text().splitlines()}
        for row in block.lines:
            assert self.here(row) in written, f'{name} has no line {row!r}'

    def expect(self, command: str, expected: List[str], printed: str) -> None:
        for wanted in expected:
            assert normalized(self.here(wanted)) in normalized(printed), \
                f'{command}\n  printed:\n{printed}\n  page: {wanted}\n{self.logs()}'

    def logs(self) -> str:
        return '\n'.join(f'-- {process.args[-1]}:\n{node_output(process)}'
                         for process in self.background)

    def stop(self) -> Dict[str, int]:
        """Stop the background processes, the last started first (SIGTERM, as Ctrl-C)."""
        codes = {}
        for process in reversed(self.background):
            process.terminate()
            try:
                codes[process.args[-1]] = process.wait(timeout=20)
            except subprocess.TimeoutExpired:
                process.kill()
                codes[process.args[-1]] = process.wait()
            process.log.close()
        return codes


def test_the_quick_start_works_as_written(tmp_path):
    page = [block for block in blocks(PAGE) if not block.language.startswith('{')]
    markers = [block.marker for block in page]
    assert all(markers), f'a block of the quick start has no test marker: {markers}'
    quick = QuickStart(tmp_path)
    try:
        for block in page:
            background = BACKGROUND.fullmatch(block.marker)
            if block.marker == 'environment':
                quick.environment(block)
            elif background:
                quick.start(block, background.group(1))
            elif block.marker == 'run':
                quick.run(block)
            elif block.marker.startswith('file '):
                quick.write(block, block.marker[len('file '):])
            elif block.marker.startswith('lines of '):
                quick.lines_of(block, block.marker[len('lines of '):])
            else:
                assert block.marker.startswith('not run ('), block.marker
    finally:
        codes = quick.stop()
    assert set(codes.values()) == {0}, f'{codes}\n{quick.logs()}'


@pytest.fixture(autouse=True)
def _no_leftover_link(tmp_path):
    yield
    assert not os.path.lexists(tmp_path / 'drive_bridge_line'), 'the simulator left its link'
