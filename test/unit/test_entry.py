"""The node's entry point blocks the exit signals before anything can start a thread."""

import signal
import subprocess
import sys

# Imports the entry point, then runs it (--help) with a finder that notes the signal mask of
# the moment the process module (rclpy, DDS, numpy: threads) begins to be imported.
PROBE = """
import os, signal, sys
import drive_bridge.ros.node.entry as entry
print(len(os.listdir('/proc/self/task')), 'rclpy' in sys.modules)

class Note:
    def find_spec(self, name, path=None, target=None):
        if name == 'drive_bridge.ros.node.process':
            print(*sorted(int(s) for s in signal.pthread_sigmask(signal.SIG_BLOCK, [])))
        return None

sys.meta_path.insert(0, Note())
sys.exit(entry.main(['drive_bridge_node', '--help']))
"""


def test_the_exit_signals_are_blocked_before_anything_starts_a_thread():
    done = subprocess.run([sys.executable, '-c', PROBE], capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert lines[0] == '1 False'  # importing the entry point: one thread, no rclpy
    assert {signal.SIGINT, signal.SIGTERM, signal.SIGHUP} <= {int(n) for n in lines[1].split()}
    assert lines[2].startswith('usage: drive_bridge_node')
