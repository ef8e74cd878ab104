"""Case processes forked from one warm template per campaign: no interpreter start, imports or spec load per case.

The *zygote* imports the worker, loads the spec and dictionaries once, and
then forks one child per case on request, so a case spends no CPU on
Python's start-up (figures: docs/performance.md, "pipes"). A child is a case
process as any other — its own session and process group, dying with the
zygote, which dies with the campaign — that forks its recorder in turn
(:mod:`.forked`), reads its payload and writes its outcome on a socket of
its own, and writes its stderr to the case's ``case.log``.

The zygote stays one thread with no Zenoh session (forking is safe), reaps
its children, and exits once the campaign closes its control socket.
Protocol on the control socket (:mod:`astaa_deft.io.pipe_messages` frames):
the campaign sends a :class:`ForkRequest` with a socket end attached
(SCM_RIGHTS); the zygote forks, closes its copy and answers :class:`Forked`
(the child's pid). On the case's socket: a ``CaseMessage`` in, an
``OutcomeMessage`` out (:mod:`.payload`).
"""

from __future__ import annotations

import contextlib
import os
import select
import signal
import socket
import subprocess
import sys
import threading
import time
import traceback
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, ClassVar, NoReturn

from astaa_deft.engine.bus.process_launch import fork_session_child, start
from astaa_deft.engine.bus.processes import process_running, python_module
from astaa_deft.io import pipe_messages
from astaa_deft.io.inputfile import SPEC, read_input
from astaa_deft.io.pipe_messages import FieldlessMessage, FrameError
from astaa_deft.model.json import JsonObject, JsonValue

if TYPE_CHECKING:  # the worker's imports are the template's to load, not the campaign's
    from astaa_deft.orchestration.campaign.worker import ParsedSpec, Preloaded

REAP_SECONDS = 0.5
FORK_TIMEOUT = 60.0


@dataclass(frozen=True)
class ForkRequest(FieldlessMessage):
    """To the template: fork a case process for the socket end sent with this message (SCM_RIGHTS)."""

    TAG: ClassVar[str] = "fork"


@dataclass(frozen=True)
class Forked:
    """From the template: the case process it forked."""

    TAG: ClassVar[str] = "forked"
    pid: int

    def to_json(self) -> JsonObject:
        return {"pid": self.pid}

    @classmethod
    def from_json(cls, data: JsonObject) -> Forked:
        pid: JsonValue = data["pid"]
        if not isinstance(pid, int) or pid <= 0:
            raise ValueError(f"a pid, not {pid!r}")
        return cls(pid)


class Zygote:
    """The campaign's side: start the template process, ask it for case processes (thread-safe)."""

    def __init__(self, spec: str, dictionaries: list[str]) -> None:
        """Start the template for ``spec`` and ``dictionaries``; raises the ``OSError`` of the start."""
        self._control, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            self.process = start([*python_module("astaa_deft.orchestration.campaign.zygote"), str(theirs.fileno()),
                                  spec, *dictionaries], pass_fds=(theirs.fileno(),))
        except BaseException:
            self._control.close()
            raise
        finally:
            theirs.close()
        self._lock = threading.Lock()
        self._control.settimeout(FORK_TIMEOUT)  # its start (imports, the spec) included, on a loaded machine

    def alive(self) -> bool:
        """Whether the template process runs."""
        return self.process.poll() is None

    def fork(self) -> tuple[int, socket.socket]:
        """A new case process: (its pid, the socket to send its payload on and read its outcome from).

        Raises ``OSError`` when the template did not fork (it is then killed:
        a late answer would be taken for the next request's).
        """
        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
        answer: Forked | None = None
        try:
            with self._lock:
                socket.send_fds(self._control, [pipe_messages.encode(ForkRequest())], [theirs.fileno()])
                answer = pipe_messages.receive(self._control.recv, (Forked,), source="the case template's answer")
        except (OSError, FrameError):  # a timeout included
            self.process.kill()
        finally:
            theirs.close()
        if answer is None:
            ours.close()
            raise OSError("the case template process did not fork")
        return answer.pid, ours

    def close(self) -> None:
        """Close the control socket (the template then exits once its cases have) and wait for the template."""
        with contextlib.suppress(OSError):
            self._control.close()
        try:
            self.process.wait(timeout=10.0)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait(timeout=5.0)


def stop_group(pid: int, grace: float) -> None:
    """Stop a forked case's process group (not our child: wait until it is gone, then kill)."""
    for sig, wait in ((signal.SIGTERM, grace), (signal.SIGKILL, 2.0)):
        try:
            os.killpg(pid, sig)
        except (ProcessLookupError, PermissionError):
            return
        deadline = time.monotonic() + wait
        while time.monotonic() < deadline:
            if not process_running(pid):
                return
            time.sleep(0.05)


# ---------------------------------------------------------------- the template process


class _Requests:
    """The template's reader of its control socket: frames, with the socket ends sent along (SCM_RIGHTS)."""

    def __init__(self, control: socket.socket) -> None:
        self._control = control
        self.fds: list[int] = []

    def read(self, size: int) -> bytes:
        data, fds, _, _ = socket.recv_fds(self._control, size, 1)
        self.fds.extend(fds)
        return data

    def next(self) -> int | None:
        """The socket end of the next fork request; None when the campaign closed its end.

        Raises :class:`FrameError` for a garbled request or one without a socket end.
        """
        request = pipe_messages.receive(self.read, (ForkRequest,), source="the case template's control socket")
        if request is None:
            return None
        if len(self.fds) != 1:
            for fd in self.fds:
                os.close(fd)
            self.fds.clear()
            raise FrameError(f"the case template's control socket: a fork request with {len(self.fds)} sockets")
        return self.fds.pop()


def main(argv: list[str] | None = None) -> int:
    """The template process: ``CONTROL_FD SPEC [DICTIONARY …]``; forks a case per request until the campaign
    closes the control socket, then reaps its cases; its exit code."""
    argv = sys.argv[1:] if argv is None else argv
    control = socket.socket(fileno=int(argv[0]))
    spec, dictionaries = argv[1], tuple(argv[2:])
    from astaa_deft.model.errors import InputError
    from astaa_deft.engine.spec.loader import load_spec_text
    from astaa_deft.orchestration.campaign.worker import ParsedSpec, Preloaded

    preloaded: Preloaded | None = None
    for_recorder: ParsedSpec | None = None
    with contextlib.suppress(InputError):  # a bad spec is each case's error to report (execute loads it again)
        preloaded = Preloaded.load(spec, dictionaries)
    with contextlib.suppress(Exception):  # the recorder's own parse of the text (see forked.py)
        text = read_input(spec, SPEC).decode("utf-8")
        for_recorder = ParsedSpec(text, load_spec_text(text, name=Path(spec).name))
    requests = _Requests(control)
    while True:
        ready, _, _ = select.select([control], [], [], REAP_SECONDS)
        _reap()
        if not ready:
            continue
        try:
            fd = requests.next()
        except (OSError, FrameError):
            break
        if fd is None:  # the campaign closed its end
            break
        pid = fork_session_child("a case process")  # this process runs one thread and no Zenoh session
        if pid == 0:
            control.close()
            _case(fd, Path(spec), _Preload(preloaded, for_recorder))  # never returns
        os.close(fd)
        pipe_messages.send_socket(control, Forked(pid))
    while _reap(block=True):
        pass
    return 0


def _reap(block: bool = False) -> bool:
    """Reap finished case processes (their CPU counts as ours, and so as the campaign's); False when none is left."""
    while True:
        try:
            pid, _ = os.waitpid(-1, 0 if block else os.WNOHANG)
        except ChildProcessError:
            return False
        if pid == 0:
            return True
        if block:
            return True


@dataclass(frozen=True)
class _Preload:
    """What the template loaded for its cases (None where it could not)."""

    worker: Preloaded | None
    recorder: ParsedSpec | None


def _case(fd: int, spec: Path, preload: _Preload) -> NoReturn:
    """One case in a forked child: its recorder forked ahead, payload in, outcome out (module doc); exits."""
    from astaa_deft.orchestration.campaign import worker

    code = 1
    try:
        conn = socket.socket(fileno=fd)
        recorder = worker.recorder_ahead(spec, preload.recorder)
        payload = worker.receive_case(conn.recv, source="the case's payload socket")
        run_dir = Path(payload.run_dir)
        run_dir.mkdir(parents=True, exist_ok=True)
        err = os.open(run_dir / "case.log", os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        os.dup2(err, 2)
        os.close(err)
        sys.stderr = open(2, "w", encoding="utf-8", closefd=False)  # noqa: SIM115 - the process's own stream
        pipe_messages.send_socket(conn, worker.run_received(payload, preload.worker, recorder))
        conn.close()
        code = 0
    except BaseException:  # noqa: BLE001 - a forked child must never return into the template's loop
        traceback.print_exc()
    finally:
        with contextlib.suppress(Exception):
            sys.stderr.flush()
        os._exit(code)


if __name__ == "__main__":
    sys.exit(main())
