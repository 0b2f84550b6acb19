"""
What the package's terminal commands share: their exit when the reader of their output goes.

``drive-bridge monitor ... | head -3`` or ``drive_bridge_ctl echo ... | head -2``: once the
reader has gone, the next write raises ``BrokenPipeError``. The command then ends as SIGPIPE
would end a C program, with :data:`EXIT_BROKEN_PIPE` and nothing on stderr, and points its
stdout at /dev/null first, so that Python's flush at exit raises nothing either (Python's note
on SIGPIPE, in the ``signal`` module's documentation).
"""

import os
import sys

EXIT_BROKEN_PIPE = 141  # the reader of stdout went away: as a program SIGPIPE ended


def drop_stdout() -> None:
    """Point stdout at /dev/null, so that nothing more is written to a closed pipe."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):  # no descriptor behind sys.stdout
        pass
    finally:
        os.close(devnull)
