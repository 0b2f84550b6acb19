"""
Bench helpers: the machine a bench ran on, and a process's CPU per thread.

The CPU comes from the scheduler's own accounting, not from ``/proc/<pid>/stat`` (which
this kind of kernel fills by sampling at each tick, CONFIG_TICK_CPU_ACCOUNTING, too coarse
for a thread that runs 100 us at a time): ``/proc/<pid>/task/<tid>/schedstat`` gives the
nanoseconds each thread spent on a CPU, and ``/proc/<pid>/task/<tid>/sched`` how often it
gave the CPU up by itself (``nr_voluntary_switches``: each one a wait it woke from) or was
preempted (``nr_involuntary_switches``). Python threads all carry the process's name in
``comm``; their Python names (``drive-bridge-bus``, ``ros-executor``, ...) are read with
``py-spy dump`` where py-spy is installed (``$PY_SPY``, ``py-spy`` on the PATH, or
``/tmp/pyspy/bin/py-spy``), else they are shown as ``python``.
"""

from dataclasses import dataclass
import os
import platform
import re
import shutil
import subprocess
import time
from typing import Dict, List, Optional

PY_SPY_CANDIDATES = ('/tmp/pyspy/bin/py-spy',)


@dataclass(frozen=True)
class ThreadSample:
    """One thread's counters at one moment."""

    name: str  # comm: the native thread's name
    cpu_ns: int
    voluntary: int  # waits it woke from
    involuntary: int  # preemptions


def cpu_model() -> str:
    """Return the CPU's model name from /proc/cpuinfo."""
    try:
        with open('/proc/cpuinfo') as stream:
            for line in stream:
                if line.startswith('model name'):
                    return line.split(':', 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or 'unknown CPU'


def machine() -> str:
    """Return the machine in one line: kernel, CPU, cores, Python, load now."""
    load = ', '.join(f'{value:.2f}' for value in os.getloadavg())
    return (f'machine: {platform.system()} {platform.release()} {platform.machine()}, '
            f'{cpu_model()}, {os.cpu_count()} cores, Python {platform.python_version()}; '
            f'load average {load}')


def load() -> str:
    """Return the load averages (1, 5, 15 minutes) in one line."""
    return 'load average ' + ', '.join(f'{value:.2f}' for value in os.getloadavg())


def _switches(sched_path: str) -> Dict[str, int]:
    counts = {}
    with open(sched_path) as stream:
        for line in stream:
            key, _, value = line.partition(':')
            key = key.strip()
            if key in ('nr_voluntary_switches', 'nr_involuntary_switches'):
                counts[key] = int(value)
    return counts


def sample(pid: int) -> Dict[int, ThreadSample]:
    """Return tid -> counters for every thread of ``pid`` now."""
    threads = {}
    for tid in os.listdir(f'/proc/{pid}/task'):
        base = f'/proc/{pid}/task/{tid}'
        try:
            with open(f'{base}/comm') as stream:
                name = stream.read().strip()
            with open(f'{base}/schedstat') as stream:
                cpu_ns = int(stream.read().split()[0])
            switches = _switches(f'{base}/sched')
        except (FileNotFoundError, ProcessLookupError):  # the thread ended meanwhile
            continue
        threads[int(tid)] = ThreadSample(name, cpu_ns, switches['nr_voluntary_switches'],
                                         switches['nr_involuntary_switches'])
    return threads


def py_spy() -> Optional[str]:
    """Return the py-spy executable, if there is one."""
    for candidate in (os.environ.get('PY_SPY'), shutil.which('py-spy'), *PY_SPY_CANDIDATES):
        if candidate and os.access(candidate, os.X_OK):
            return candidate
    return None


def python_thread_names(pid: int) -> Dict[int, str]:
    """Return tid -> Python thread name, by ``py-spy dump`` (empty without py-spy)."""
    executable = py_spy()
    if executable is None:
        return {}
    try:
        output = subprocess.run([executable, 'dump', '--pid', str(pid)], capture_output=True,
                                text=True, timeout=30).stdout
    except (OSError, subprocess.TimeoutExpired):
        return {}
    return {int(tid): name for tid, name in re.findall(r'^Thread (\d+) \([^)]*\): "([^"]*)"',
                                                       output, re.MULTILINE)}


@dataclass(frozen=True)
class ThreadShare:
    """One thread's share over a window."""

    tid: int
    name: str
    cpu_pct: float  # of one core
    wakeups_per_s: float  # voluntary switches: waits it woke from
    preempted_per_s: float


def shares(before: Dict[int, ThreadSample], after: Dict[int, ThreadSample], seconds: float,
           names: Dict[int, str]) -> List[ThreadShare]:
    """Return each thread's share over the window, the busiest first."""
    rows = []
    for tid, now in after.items():
        then = before.get(tid, ThreadSample(now.name, 0, 0, 0))
        name = names.get(tid, 'python' if now.name.startswith('python') else now.name)
        rows.append(ThreadShare(tid, name, 100.0 * (now.cpu_ns - then.cpu_ns) / 1e9 / seconds,
                                (now.voluntary - then.voluntary) / seconds,
                                (now.involuntary - then.involuntary) / seconds))
    return sorted(rows, key=lambda row: row.cpu_pct, reverse=True)


@dataclass(frozen=True)
class Window:
    """A process's per-thread counters at the start and the end of a measurement window."""

    started_s: float  # time.monotonic()
    ended_s: float
    before: Dict[int, ThreadSample]
    after: Dict[int, ThreadSample]

    @property
    def seconds(self) -> float:
        return self.ended_s - self.started_s

    def shares(self, names: Dict[int, str]) -> List[ThreadShare]:
        """Return each thread's share over the window (:func:`shares`)."""
        return shares(self.before, self.after, self.seconds, names)


def measure_window(pid: int, window_s: float) -> Window:
    """Sample process ``pid`` now and ``window_s`` later (sleeping meanwhile)."""
    started_s = time.monotonic()
    before = sample(pid)
    time.sleep(window_s)
    after = sample(pid)
    return Window(started_s, time.monotonic(), before, after)


def total_pct(rows: List[ThreadShare]) -> float:
    """Return the process's CPU over the window, % of one core (threads alive at its end)."""
    return sum(row.cpu_pct for row in rows)


def by_name(rows: List[ThreadShare]) -> Dict[str, float]:
    """Return CPU % of one core by thread name (threads of one name summed)."""
    totals: Dict[str, float] = {}
    for row in rows:
        totals[row.name] = totals.get(row.name, 0.0) + row.cpu_pct
    return totals


def table(rows: List[ThreadShare], pid: int, limit: int = 8) -> List[str]:
    """Return the busiest threads as printed lines."""
    lines = ['  tid      thread              % of one core  wake-ups/s  preempted/s']
    for row in rows[:limit]:
        label = f'{row.name} (main)' if row.tid == pid else row.name
        lines.append(f'  {row.tid:<7d}  {label[:18]:18s}  {row.cpu_pct:13.2f}  '
                     f'{row.wakeups_per_s:10.0f}  {row.preempted_per_s:11.0f}')
    return lines
