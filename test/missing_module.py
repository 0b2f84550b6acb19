"""Run one of the package's commands as if some modules were not installed."""

import subprocess
import sys
from typing import List

# Runs the console script's entry point (as its wrapper does) behind an import finder that
# answers ModuleNotFoundError for the blocked packages, as an interpreter without them does.
_RUNNER = """
import sys
from importlib.metadata import entry_points
BLOCKED = set(sys.argv[1].split(','))
class NotInstalled:
    def find_spec(self, name, path=None, target=None):
        if name.partition('.')[0] in BLOCKED:
            raise ModuleNotFoundError(f'No module named {name!r}', name=name)
sys.meta_path.insert(0, NotInstalled())
[entry] = entry_points(group='console_scripts', name=sys.argv[2])
sys.argv[:] = sys.argv[2:]
sys.exit(entry.load()())
"""


def run_without(modules: List[str], command: str, args: List[str],
                timeout_s: float = 60.0) -> subprocess.CompletedProcess:
    """Run the console script ``command`` with ``args`` while ``modules`` cannot be imported."""
    return subprocess.run([sys.executable, '-c', _RUNNER, ','.join(modules), command] + args,
                          capture_output=True, text=True, timeout=timeout_s,
                          stdin=subprocess.DEVNULL)
