"""The node's entry point blocks the exit signals before anything can start a thread."""

import os
import signal
import subprocess
import sys

PROBE = '''
import os, signal, sys
import drive_bridge.ros.entry as entry
print(len(os.listdir('/proc/self/task')), 'rclpy' in sys.modules,
      'drive_bridge.ros.process' in sys.modules)
entry.block_in_this_thread()
print(*sorted(int(s) for s in signal.pthread_sigmask(signal.SIG_BLOCK, [])))
'''


def test_importing_the_entry_point_starts_no_thread_and_imports_no_ros():
    done = subprocess.run([sys.executable, '-c', PROBE], capture_output=True, text=True,
                          timeout=60, env={**os.environ, 'PYTHONWARNINGS': 'ignore'})
    assert done.returncode == 0, done.stderr
    counts, mask = done.stdout.splitlines()
    assert counts == '1 False False'
    assert {signal.SIGINT, signal.SIGTERM, signal.SIGHUP} <= {int(n) for n in mask.split()}
