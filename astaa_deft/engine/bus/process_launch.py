"""Every child process of the tool starts here (the process model: docs/architecture.md, "Processes").

Ways in, one set of rules:

* :func:`start` — a program (a module, the recorder, the bus router, the
  reaper, a case worker, a replay worker, pytest): a ``subprocess.Popen``,
  in a session of its own (its process group's id is its pid: it is stopped
  by group). It is forked from one long-lived thread of this process, never
  from the caller's: Linux sends the parent-death signal when the *thread*
  that forked a child ends, so a child started from a pool's thread would be
  killed when that thread ends. No ``preexec_fn`` (Python code between fork
  and exec may deadlock in a process that has other threads): with
  ``die_with_tool`` the child is first a small wrapper that sets its own
  parent-death signal, checks that its parent is still the tool (the tool
  may have died before the signal was armed), then execs the command.
* :func:`run` — :func:`start`, wait for the end (with a time limit), the output.
* :func:`fork_child` — a child forked without exec that runs a function of
  this process with its memory (a recorder forked from a warm worker), handed
  back as a :class:`ForkedChild`, driven like a ``Popen``.
* :func:`fork_session_child` — a child forked without exec that leads a
  session of its own and dies with this process, for a caller that sets up
  its channels itself (the case template's case processes: a socket each).
* :func:`guarded_fork` — a bare ``os.fork`` for code that manages its
  children itself (forked replay's copies, which must share this process's
  group), after :func:`ensure_fork_safe`.

The messages on the pipes and sockets to these children are framed by
:mod:`astaa_deft.io.pipe_messages`.

Nothing here signals or waits for a process it did not start.
"""

from __future__ import annotations

import contextlib
import ctypes
import gc
import os
import signal
import subprocess
import sys
import threading
import time
import traceback
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import Future
from queue import SimpleQueue
from typing import IO, NoReturn, TypeAlias, TypeVar

from astaa_deft.model.errors import AstaaDeftError
from astaa_deft.engine.bus.processes import stop_process

PR_SET_PDEATHSIG = 1
# How long a fork waits for other Python threads to end before it refuses: a Zenoh session's callback thread
# ends soon after its session closes, later on a loaded machine; a thread that runs on is refused after it.
THREADS_ENDING_WAIT_S = 2.0

# The wrapper (run as ``python -I -S -c``: no site, no environment, no current directory; only the standard
# library): arm the parent-death signal, make sure the parent is still the one that started us — if it died
# before prctl, nothing would ever signal us: exit as if the signal had come —, then become the command. Its argv:
# the tool's pid, the signal, the fd to report an exec failure on (its errno; exit 127 then, as a shell's), the
# command.
_WRAPPER = """\
import os, sys
parent, sig, report = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3])
try:
    import ctypes
    ctypes.CDLL(None, use_errno=True).prctl(1, sig, 0, 0, 0)
except (OSError, AttributeError):
    pass
if os.getppid() != parent:
    os._exit(128 + sig)
os.set_inheritable(report, False)
try:
    os.execvp(sys.argv[4], sys.argv[4:])
except OSError as exc:
    os.write(report, str(exc.errno).encode())
    os._exit(127)
"""


class UnsafeFork(AstaaDeftError):
    """An ``os.fork`` asked for while other threads run (internal: the caller must fork while single-threaded)."""


# -- the thread every child is forked from -------------------------------------------------------------

ResultT = TypeVar("ResultT")


class _Starter:
    """One daemon thread, alive as long as the process, that runs every ``Popen`` of :func:`start`.

    Idle, it waits on its queue and holds nothing a forked child would need
    (the child gets a starter of its own): a fork holds :attr:`working`, so
    the starter is idle throughout, and does not count it as another thread.
    """

    def __init__(self) -> None:
        self._jobs: SimpleQueue[Callable[[], None]] = SimpleQueue()  # each sets the future its caller waits on
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()
        self.working = threading.Lock()  # held while a child is started, and by a fork

    @property
    def thread(self) -> threading.Thread | None:
        """The starter thread (None until the first start)."""
        return self._thread

    def call(self, job: Callable[[], ResultT], undo: Callable[[ResultT], object] | None = None) -> ResultT:
        """``job()`` run in the starter thread; its result, or its exception raised here. Interrupted while
        waiting (Ctrl-C, SIGTERM as one), the job still finishes in the starter: ``undo`` then gets its result
        (the child it started is stopped, never left running unowned) before the interrupt goes on."""
        with self._lock:
            if self._thread is None:
                self._thread = threading.Thread(target=self._serve, name="process-starter", daemon=True)
                self._thread.start()
            thread = self._thread
        if threading.current_thread() is thread:
            return job()
        future: Future[ResultT] = Future()

        def run() -> None:
            try:
                future.set_result(job())
            except BaseException as exc:  # noqa: BLE001 - handed to the caller, whatever it is
                future.set_exception(exc)

        self._jobs.put(run)
        try:
            return future.result()
        except BaseException:
            if undo is not None:
                with contextlib.suppress(BaseException):  # the job's own error: nothing to undo
                    undo(future.result())  # waits for the job, then undoes it
            raise

    def _serve(self) -> None:
        while True:
            run = self._jobs.get()
            with self.working:
                run()


_starter = _Starter()


def _new_starter_after_fork() -> None:
    # A forked child has none of its parent's threads: its first start makes its own starter.
    global _starter
    _starter = _Starter()


os.register_at_fork(after_in_child=_new_starter_after_fork)


# -- programs ----------------------------------------------------------------------------------------

# A child's standard stream as ``subprocess.Popen`` takes it: a file descriptor or one of its
# constants (DEVNULL, PIPE, STDOUT), an open file (binary or text), or None (the tool's own).
Stream: TypeAlias = int | IO[bytes] | IO[str] | None


def start(argv: Sequence[str], *, cwd: str | None = None, env: Mapping[str, str] | None = None,
          stdin: Stream = subprocess.DEVNULL, stdout: Stream = subprocess.DEVNULL, stderr: Stream = subprocess.DEVNULL,
          text: bool = False, pass_fds: Sequence[int] = (),
          die_with_tool: bool = True, death_signal: signal.Signals = signal.SIGTERM) -> subprocess.Popen:
    """Start ``argv`` as a child in its own session; return its ``Popen`` once the command itself runs.

    ``stdin``/``stdout``/``stderr``, ``cwd``, ``env``, ``text`` and
    ``pass_fds`` mean what they mean to ``subprocess.Popen``; the streams
    default to ``/dev/null``. ``die_with_tool``: the child gets
    ``death_signal`` when this process ends, even by SIGKILL (Linux; the
    reaper, which must outlive the tool, is started without). Raises the
    ``OSError`` ``Popen`` would (``FileNotFoundError``, ``PermissionError``)
    when the command cannot be executed.
    """
    argv = [str(part) for part in argv]
    if not die_with_tool:
        return _starter.call(lambda: subprocess.Popen(
            argv, cwd=cwd, env=env, stdin=stdin, stdout=stdout, stderr=stderr, text=text,
            pass_fds=tuple(pass_fds), start_new_session=True), undo=_kill_started)
    report_read, report_write = os.pipe()
    try:
        wrapped = [sys.executable, "-I", "-S", "-c", _WRAPPER, str(os.getpid()), str(int(death_signal)),
                   str(report_write), *argv]
        process: subprocess.Popen = _starter.call(lambda: subprocess.Popen(
            wrapped, cwd=cwd, env=env, stdin=stdin, stdout=stdout, stderr=stderr, text=text,
            pass_fds=(*pass_fds, report_write), start_new_session=True), undo=_kill_started)
        process.args = argv  # what the caller started, in messages and TimeoutExpired
        os.close(report_write)
        report_write = -1
        with os.fdopen(report_read, "rb") as report:
            report_read = -1
            try:
                failure = report.read()  # empty once the command runs (the fd closes on exec) or the wrapper died
            except BaseException:  # interrupted while it starts: the caller never gets it, so it is stopped here
                _kill_started(process)
                raise
    finally:
        for fd in (report_read, report_write):
            if fd >= 0:
                os.close(fd)
    if failure:
        process.wait()
        code = int(failure)
        raise OSError(code, os.strerror(code), argv[0])
    return process


def _kill_started(process: subprocess.Popen) -> None:
    """Stop a child :func:`start` started but could not hand over (its caller was interrupted): its group."""
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(process.pid, signal.SIGKILL)
    process.wait()


def run(argv: Sequence[str], *, timeout: float | None, cwd: str | None = None,
        env: Mapping[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    """Run ``argv`` (:func:`start`) to its end; its exit code and output (stdout and stderr, as text).

    Raises ``subprocess.TimeoutExpired`` after stopping the child's whole
    process group when it runs longer than ``timeout`` seconds (None: no
    limit), and the ``OSError`` of :func:`start`.
    """
    process = start(argv, cwd=cwd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        out, err = process.communicate(timeout=timeout)
    except BaseException:
        stop_process(process, grace=5.0)
        process.communicate()
        raise
    return subprocess.CompletedProcess(process.args, process.returncode, out, err)


# -- forks -------------------------------------------------------------------------------------------


def foreign_threads() -> int:
    """Threads of this process that Python's ``threading`` did not start (Zenoh's runtime, a BLAS pool).

    0 where ``/proc`` cannot tell.
    """
    try:
        tasks = len(os.listdir("/proc/self/task"))
    except OSError:
        return 0
    return max(0, tasks - threading.active_count())


def _other_python_threads() -> list[threading.Thread]:
    """Python threads besides this one and the idle process starter."""
    current, starter = threading.current_thread(), _starter.thread
    return [t for t in threading.enumerate() if t is not current and t is not starter]


def fork_is_safe(*, native_threads_ok: bool = False) -> bool:
    """Whether this process may fork now: no other Python thread and (unless ``native_threads_ok``) no native one.

    The process starter (:func:`start`'s thread) does not count: a fork waits until it is idle.
    """
    return hasattr(os, "fork") and not _other_python_threads() and (native_threads_ok or foreign_threads() == 0)


def ensure_fork_safe(what: str, *, native_threads_ok: bool = False) -> None:
    """Raise :class:`UnsafeFork` naming ``what`` unless :func:`fork_is_safe`.

    A forked child holds only the forking thread: a lock another thread held
    at that moment (the import lock, logging's, a stream's, a native
    runtime's) stays locked in the child forever. ``native_threads_ok``
    admits threads Python did not start, for children that never touch what
    they own (a forked replay runs only the planner; a BLAS pool, which
    numpy starts on import, stops itself across a fork).
    """
    if not hasattr(os, "fork"):
        raise UnsafeFork(f"{what}: this system cannot fork")
    others = _other_python_threads()
    if others:  # a thread on its way out (a closed Zenoh session's callback thread) may end in a moment
        deadline = time.monotonic() + THREADS_ENDING_WAIT_S
        for thread in others:
            thread.join(max(0.0, deadline - time.monotonic()))
        others = _other_python_threads()
    native = foreign_threads()
    if others or (native and not native_threads_ok):
        names = ", ".join(t.name for t in others)
        raise UnsafeFork(f"{what}: forked only from a single-threaded process, but {len(others)} other Python "
                         f"thread(s) run" + (f" ({names})" if names else "")
                         + (f" and {native} native one(s)" if native else "")
                         + "; fork before starting threads or a Zenoh session, or start a process instead")


# True in a forked child: what its parent had when it forked stays frozen here for good (guarded_fork).
_inherited_frozen = False


def guarded_fork(what: str, *, native_threads_ok: bool = False) -> int:
    """``os.fork()`` after :func:`ensure_fork_safe` (same arguments); 0 in the child, its pid in the parent.

    The child never collects what its parent had when it forked: the garbage among it may be a Zenoh
    session or subscriber nobody closed, whose finaliser waits for the Zenoh runtime's threads — which a
    forked child does not have, so it would wait forever. So everything is frozen (``gc.freeze``) across the
    fork, and thawed again only in a process that was not itself forked: a forked child that forks collects
    its own garbage first and keeps the rest frozen, since a thaw would hand its parent's garbage to the
    collector too.
    """
    global _inherited_frozen
    with _starter.working:  # no child being started meanwhile
        ensure_fork_safe(what, native_threads_ok=native_threads_ok)
        if _inherited_frozen:
            gc.collect()  # this process's own garbage only: its parent's is frozen
        gc.freeze()
        pid = -1
        try:
            pid = os.fork()
        finally:
            if pid == 0:
                _inherited_frozen = True
            elif not _inherited_frozen:
                gc.unfreeze()
        return pid


def die_with_parent(parent: int, sig: signal.Signals = signal.SIGTERM) -> None:
    """In a child just forked from ``parent``: get ``sig`` when the parent ends (Linux); exit if it has already."""
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, int(sig), 0, 0, 0)
    if os.getppid() != parent:
        os._exit(128 + int(sig))


def fork_session_child(what: str) -> int:
    """:func:`guarded_fork` for a child that leads a session of its own and gets SIGTERM when this process ends.

    0 in the child (which must end with ``os._exit``), its pid here once the
    child leads its group (as ``Popen`` returns). Raises :class:`UnsafeFork`
    naming ``what`` unless single-threaded.
    """
    parent = os.getpid()
    started_read, started_write = os.pipe()  # the child says when it leads its own group
    try:
        pid = guarded_fork(what)
    except UnsafeFork:
        os.close(started_read)
        os.close(started_write)
        raise
    if pid == 0:
        os.close(started_read)
        os.setsid()
        die_with_parent(parent)
        os.write(started_write, b"1")
        os.close(started_write)
        return 0
    os.close(started_write)
    os.read(started_read, 1)  # b"" if it died first: the caller finds out when it waits
    os.close(started_read)
    return pid


class ForkedChild:
    """A child of :func:`fork_child`: the part of ``subprocess.Popen`` the tool uses (pid, pipes, poll, wait)."""

    def __init__(self, pid: int, stdin: IO[str], stdout: IO[str]) -> None:
        self.pid = pid
        self.args = [f"<forked {pid}>"]
        self.stdin: IO[str] | None = stdin
        self.stdout: IO[str] | None = stdout
        self.returncode: int | None = None
        self._lock = threading.Lock()

    def poll(self) -> int | None:
        """Its exit code once it has exited (reaped here), else None; thread-safe."""
        with self._lock:
            if self.returncode is None:
                try:
                    pid, status = os.waitpid(self.pid, os.WNOHANG)
                except ChildProcessError:  # reaped elsewhere: its code is lost, as Popen says then too
                    self.returncode = 0
                else:
                    if pid:
                        self.returncode = os.waitstatus_to_exitcode(status)
            return self.returncode

    def wait(self, timeout: float | None = None) -> int:
        """Its exit code, waiting up to ``timeout`` seconds (None: no limit); raises ``subprocess.TimeoutExpired``."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while (code := self.poll()) is None:
            if deadline is not None and time.monotonic() >= deadline:
                raise subprocess.TimeoutExpired(self.args, timeout or 0.0)
            time.sleep(0.01)
        return code


def fork_child(body: Callable[[], int], *, what: str) -> ForkedChild:
    """Fork a child that runs ``body()`` (its return value: the exit code) with text pipes on stdin and stdout.

    The child leads a session of its own, gets SIGTERM when this process
    ends, has stderr on ``/dev/null`` and no other file of ours open; it
    leads its group before this returns (:func:`fork_session_child`). Call
    it while single-threaded (raises :class:`UnsafeFork` otherwise, naming ``what``).
    """
    stdin_read, stdin_write = os.pipe()
    stdout_read, stdout_write = os.pipe()
    try:
        pid = fork_session_child(what)
    except UnsafeFork:
        for fd in (stdin_read, stdin_write, stdout_read, stdout_write):
            os.close(fd)
        raise
    if pid == 0:
        _run_forked_body(body, stdin_read, stdout_write)
    for fd in (stdin_read, stdout_write):
        os.close(fd)
    return ForkedChild(pid, open(stdin_write, "w", encoding="utf-8"), open(stdout_read, encoding="utf-8"))


def _run_forked_body(body: Callable[[], int], stdin_fd: int, stdout_fd: int) -> NoReturn:
    """In a child of :func:`fork_child`: its streams on the pipes (stderr: /dev/null), ``body()``, exit."""
    code = 1
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        for fd, target in ((stdin_fd, 0), (stdout_fd, 1), (devnull, 2)):
            os.dup2(fd, target)
        os.closerange(3, os.sysconf("SC_OPEN_MAX"))  # nothing of the parent's pipes stays open here
        sys.stdin = open(0, encoding="utf-8", closefd=False)  # noqa: SIM115 - the process's own streams
        sys.stdout = open(1, "w", encoding="utf-8", closefd=False)  # noqa: SIM115
        sys.stderr = open(2, "w", encoding="utf-8", closefd=False)  # noqa: SIM115
        code = body()
    except BaseException:  # noqa: BLE001 - a child must never return into the parent's code
        traceback.print_exc()
    finally:
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(Exception):  # exiting anyway
                stream.flush()
        os._exit(code)
