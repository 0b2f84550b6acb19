"""
Start the ROS tier's Python commands by forking a process that imported them already.

The ROS tier starts about 300 Python processes: the node (``drive_bridge.ros.node.entry``),
``drive_bridge_ctl`` and the recorder. An exec'd one spends about 0.6 s of CPU (1.3 s beside a
CPU hog) importing rclpy, the message packages and drive_bridge before it does anything, which
was about half of the tier's CPU. A fork server (a "zygote", as Android and Python's
``multiprocessing`` forkserver call it) imports them once per test process; each command is a
child forked from it that runs its module as ``python -m`` would, without the imports. The
child is a process of its own: its own pid, signal dispositions, exit status, stdio and ROS
context (rclpy is imported, never initialised, in the server).

What the test sees is a :class:`subprocess.Popen`: :class:`ForkedPopen` runs
``[sys.executable, '-m', MODULE, ...]`` for the modules in :data:`FORKED_MODULES` through the
server and anything else (other options, ``pass_fds``, a ``preexec_fn`` other than
:func:`default_signals`) as Popen would. The server forks twice, so that the command's parent
becomes the test process (a child subreaper, ``prctl(PR_SET_CHILD_SUBREAPER)``): ``wait``,
``poll`` and the exit status work as for a child it exec'd.

What differs from exec: the child starts with the modules imported, and with no thread but its
own (no thread survives a fork). So a test of the start itself (the entry's signal mask before
its imports start threads, an import error) must exec: ``ForkedPopen(..., fork=False)`` or
``start_node(..., fresh=True)``; ``DRIVE_BRIDGE_TEST_FORK=0`` execs every command of a run.
Where the server cannot start (an import fails), commands are exec'd.
"""

import atexit
import ctypes
import gc
import inspect
import json
import os
import signal
import socket
import subprocess
import sys
import threading
from typing import Dict, List, Optional, Sequence

FORKED_MODULES = (
    'drive_bridge.ros.node.entry',
    'drive_bridge.ros.ctl.cli',
    'drive_bridge.ros.record.cli',
)
# What the server imports: the commands' own modules and what they import lazily.
PRELOAD = (
    'drive_bridge.ros.node.process',
    'drive_bridge.ros.ctl.cli',
    'drive_bridge.ros.record.cli',
    'drive_bridge.ros.record.recorder',
    'rosbag2_py',
)
# Read at a process's start or its imports (the interpreter, the C libraries, the generated
# message modules): a command whose environment has other values than the server had when it
# started is exec'd.
STARTUP_VARIABLES = ('PYTHONUNBUFFERED', 'PYTHONPYCACHEPREFIX', 'PYTHONDONTWRITEBYTECODE',
                     'PYTHONPATH', 'PYTHONHOME', 'PYTHONNOUSERSITE', 'PYTHONHASHSEED',
                     'PYTHONWARNINGS', 'PYTHONDEVMODE', 'PYTHONFAULTHANDLER',
                     'PYTHONTRACEMALLOC', 'PYTHONIOENCODING', 'PYTHONUTF8', 'PYTHONOPTIMIZE',
                     'PYTHONSAFEPATH', 'OPENBLAS_NUM_THREADS', 'LANG', 'LC_ALL', 'LC_CTYPE',
                     'LD_LIBRARY_PATH', 'LD_PRELOAD', 'AMENT_PREFIX_PATH',
                     'ROS_PYTHON_CHECK_FIELDS')
# Popen._execute_child's arguments after restore_signals when none is given: gid, gids, uid,
# umask, start_new_session, process_group (Python 3.11 to 3.13).
_NO_CREDENTIALS = (None, None, None, -1, False, -1)
PR_SET_CHILD_SUBREAPER = 36
MAX_MESSAGE_BYTES = 1 << 20


def default_signals() -> None:
    """Popen ``preexec_fn``: SIGINT and SIGTERM at their defaults in the child."""
    for number in (signal.SIGINT, signal.SIGTERM):
        signal.signal(number, signal.SIG_DFL)


class ForkedPopen(subprocess.Popen):
    """A :class:`subprocess.Popen` that forks the commands of FORKED_MODULES from the server."""

    def __init__(self, args, *popen_args, fork: bool = True, **popen_kwargs):
        self._fork = fork
        self.forked = False  # True once the server forked it
        super().__init__(args, *popen_args, **popen_kwargs)

    def _execute_child(self, args, executable, preexec_fn, close_fds, pass_fds, cwd, env,
                       startupinfo, creationflags, shell, p2cread, p2cwrite, c2pread, c2pwrite,
                       errread, errwrite, restore_signals, *more):
        module = self._forkable(args, executable, preexec_fn, pass_fds, shell, env, cwd, more)
        environment = dict(os.environ if env is None else env)
        server = the_server() if module else None
        if server is not None and not server.takes(environment):
            server = None
        pid = None
        if server is not None:
            # -1: the test process's own, as it is now (pytest's capture of this test)
            stdio = [given if given != -1 else own
                     for given, own in zip((p2cread, c2pwrite, errwrite), (0, 1, 2))]
            pid = server.spawn(module, [os.fspath(arg) for arg in args[3:]], environment,
                               os.fspath(cwd or os.getcwd()), stdio,
                               preexec_fn is default_signals)
        if pid is None:
            super()._execute_child(args, executable, preexec_fn, close_fds, pass_fds, cwd, env,
                                   startupinfo, creationflags, shell, p2cread, p2cwrite,
                                   c2pread, c2pwrite, errread, errwrite, restore_signals,
                                   *more)
            return
        self.pid = pid
        self.forked = True
        self._child_created = True
        self._close_pipe_fds(p2cread, p2cwrite, c2pread, c2pwrite, errread, errwrite)

    def _forkable(self, args, executable, preexec_fn, pass_fds, shell, env, cwd,
                  more) -> Optional[str]:
        """Return the module to fork, or None where the command must be exec'd."""
        if not self._fork or os.environ.get('DRIVE_BRIDGE_TEST_FORK', '1') == '0':
            return None
        if shell or executable is not None or pass_fds or not isinstance(args, (list, tuple)):
            return None
        if preexec_fn not in (None, default_signals) or more[:6] != _NO_CREDENTIALS:
            return None  # uid, gid, umask, a session or process group of its own
        if len(args) < 3 or args[0] != sys.executable or args[1] != '-m':
            return None
        if args[2] not in FORKED_MODULES:
            return None
        if cwd is not None and not os.path.isdir(cwd):
            return None  # Popen raises, as for any command
        if env is not None and not all(isinstance(key, str) and isinstance(value, str)
                                       for key, value in env.items()):
            return None
        return args[2]


def run(args: Sequence[str], *, input=None, capture_output: bool = False,  # noqa: A002
        timeout: Optional[float] = None, check: bool = False,
        **popen_kwargs) -> subprocess.CompletedProcess:
    """:func:`subprocess.run` through :class:`ForkedPopen`."""
    if capture_output:
        popen_kwargs['stdout'] = popen_kwargs['stderr'] = subprocess.PIPE
    if input is not None:
        popen_kwargs['stdin'] = subprocess.PIPE
    with ForkedPopen(args, **popen_kwargs) as process:
        try:
            stdout, stderr = process.communicate(input, timeout=timeout)
        except subprocess.TimeoutExpired as expired:
            process.kill()
            expired.stdout, expired.stderr = process.communicate()
            raise
        except BaseException:
            process.kill()
            raise
        code = process.poll()
    result = subprocess.CompletedProcess(process.args, code, stdout, stderr)
    if check:
        result.check_returncode()
    return result


class ServerClient:
    """This test process's end of the server: one request at a time."""

    def __init__(self, process: subprocess.Popen, connection: socket.socket,
                 environment: Dict[str, str]):
        self.process = process
        self.connection = connection
        self.environment = environment  # the server's, from its start
        self.lock = threading.Lock()
        self.broken = False

    def takes(self, env) -> bool:
        """Whether a command with environment ``env`` starts as it would from the server."""
        return not self.broken and all(env.get(name) == self.environment.get(name)
                                       for name in STARTUP_VARIABLES)

    def spawn(self, module: str, arguments: List[str], env: Dict[str, str], cwd: str,
              stdio: Sequence[int], default_signals: bool) -> Optional[int]:
        """
        Fork ``module`` with ``arguments``; return its pid, or None where nothing was sent.

        Once the request is sent, the command may run: anything that goes wrong then (an
        interrupt, a pytest-timeout, the server gone) breaks the server for good and raises,
        so that a command is never started twice and no reply is read for another request.
        """
        request = json.dumps({'module': module, 'arguments': arguments, 'env': env,
                              'cwd': cwd, 'default_signals': default_signals}).encode()
        with self.lock:
            if self.broken:
                return None
            try:
                socket.send_fds(self.connection, [request], list(stdio))
            except OSError:
                self._break()
                return None
            try:
                reply = self.connection.recv(MAX_MESSAGE_BYTES)
                pid = json.loads(reply).get('pid') if reply else None
            except BaseException:
                self._break()
                raise
            if pid is None:
                self._break()
                raise RuntimeError(f'fork server: no pid for {module} (reply {reply!r}): '
                                   'it may have started; see test/fork_server.py')
            return pid

    def _break(self) -> None:
        self.broken = True
        print('fork server: broken, commands of this test process are exec-ed from now on',
              file=sys.stderr, flush=True)
        self.connection.close()

    def close(self) -> None:
        """End the server (it ends by itself when this process ends)."""
        self.connection.close()
        try:
            self.process.wait(timeout=5.0)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()


_server: Dict[str, Optional[ServerClient]] = {}
_server_lock = threading.Lock()


def the_server() -> Optional[ServerClient]:
    """Return this process's server, started on first use; None where it could not start."""
    with _server_lock:
        key = str(os.getpid())  # a forked test process starts its own
        if key not in _server:
            _server[key] = _start_server()
        return _server[key]


def _start_server() -> Optional[ServerClient]:
    libc = ctypes.CDLL(None, use_errno=True)
    if libc.prctl(PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0) != 0:
        print('fork server: prctl(PR_SET_CHILD_SUBREAPER) refused: commands are exec-ed',
              file=sys.stderr, flush=True)
        return None
    environment = dict(os.environ)
    ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
    here = os.path.dirname(os.path.abspath(__file__))
    code = (f'import sys; sys.path.insert(0, {here!r}); import fork_server; '
            f'sys.path.pop(0); sys.exit(fork_server.serve({theirs.fileno()}))')
    process = subprocess.Popen([sys.executable, '-c', code], pass_fds=[theirs.fileno()],
                               stdin=subprocess.DEVNULL)
    theirs.close()
    ours.settimeout(60.0)
    try:
        ready = ours.recv(MAX_MESSAGE_BYTES)
    except OSError:
        ready = b''
    ours.settimeout(None)
    if ready != b'ready':
        print('fork server: did not start: commands are exec-ed', file=sys.stderr, flush=True)
        ours.close()
        process.kill()
        process.wait()
        return None
    client = ServerClient(process, ours, environment)
    atexit.register(client.close)
    return client


# -- the server's side ----------------------------------------------------------------------
def serve(fd: int):
    """Import PRELOAD, then fork a command per request; in a command, run it and exit."""
    connection = socket.socket(fileno=fd)
    for name in PRELOAD:
        try:
            __import__(name)
        except ImportError:
            pass
    _load_type_supports()
    # rclpy's loggers find their caller through inspect, which maps every module to its file
    # the first time (2,500 lstat calls, 0.07 s of a node's start): map them here, once.
    inspect.getmodule(None, '(no such file)')
    # The imported objects to the permanent generation: a command's collections then neither
    # walk them nor copy their pages (each collection touched every object, and every page
    # the fork shared was copied: 0.2 s of CPU per command).
    gc.freeze()
    connection.send(b'ready')
    while True:
        try:
            message, fds, _flags, _address = socket.recv_fds(connection, MAX_MESSAGE_BYTES, 3)
        except (OSError, KeyboardInterrupt):
            return 0
        if not message:
            return 0
        request = json.loads(message)
        if len(fds) != 3:
            for received in fds:
                os.close(received)
            connection.send(json.dumps({'pid': None}).encode())
            continue
        pid = _fork_command()
        if pid == 0:
            return _run_command(connection, request, fds)
        for received in fds:
            os.close(received)
        connection.send(json.dumps({'pid': pid}).encode())


def _load_type_supports() -> None:
    """
    Load the C type support of every message and service imported.

    rclpy loads it at a type's first publisher, subscription or service: 0.25 s of a node's
    start, with numpy.
    """
    from rclpy.type_support import check_for_type_support
    interfaces = [module for name, module in list(sys.modules.items())
                  if name.rpartition('.')[2] in ('msg', 'srv', 'action')]
    for module in interfaces:
        for value in list(vars(module).values()):
            if isinstance(value, type) and hasattr(type(value), '__import_type_support__'):
                try:
                    check_for_type_support(value)
                except (AttributeError, ImportError):
                    pass


def _fork_command() -> Optional[int]:
    """Fork twice; return 0 in the command, its pid (or None) in the server."""
    read_end, write_end = os.pipe()
    middle = os.fork()
    if middle == 0:
        command = os.fork()
        if command == 0:
            os.close(read_end)
            os.close(write_end)
            return 0
        os.write(write_end, str(command).encode())
        os._exit(0)
    os.close(write_end)
    text = b''
    while True:
        chunk = os.read(read_end, 32)
        if not chunk:
            break
        text += chunk
    os.close(read_end)
    os.waitpid(middle, 0)  # when it returns, the command's parent is the test process
    return int(text) if text else None


def _run_command(connection: socket.socket, request: Dict, fds: List[int]):
    """In the forked command: take its stdio, environment and signals; run its module."""
    connection.close()
    for target, fd in enumerate(fds):
        if fd != target:
            os.dup2(fd, target)
    for fd in set(fds):
        if fd > 2:
            os.close(fd)
    os.chdir(request['cwd'])
    os.environ.clear()
    os.environ.update(request['env'])
    if request['default_signals']:
        # as in a fresh interpreter started with them at SIG_DFL
        signal.signal(signal.SIGINT, signal.default_int_handler)
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
    import runpy
    module = request['module']
    sys.modules.pop(module, None)
    sys.argv = [module] + request['arguments']
    runpy.run_module(module, run_name='__main__', alter_sys=True)
    return 0
