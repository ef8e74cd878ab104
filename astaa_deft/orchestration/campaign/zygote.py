"""Case processes forked from one warm template per campaign: no interpreter start, imports or spec load per case.

Started as a process of its own, each case's worker spent ~0.7 CPU s on
Python's start, the imports and loading the spec and dictionaries — the
same work every case, a fifth of a demo case's CPU (measured:
benchmarks/bench_campaign.py). The *zygote* does it once: a process that
imports the worker, loads the spec and dictionaries, and then forks one
child per case on request. A child is a case process as before — its own
session and process group, dying with the zygote, which dies with the
campaign — that forks its recorder in turn (:mod:`.forked`), reads its
payload and writes its outcome on a socket of its own, and writes its
stderr to the case's ``case.log``.

The zygote stays one thread with no Zenoh session (forking is safe), reaps
its children, and exits once the campaign closes its control socket.
Protocol on the control socket: the campaign sends one byte with a socket
end attached (SCM_RIGHTS); the zygote forks, closes its copy and answers the
child's pid as a line.
"""

from __future__ import annotations

import contextlib
import json
import os
import select
import signal
import socket
import subprocess
import sys
import threading
import traceback
from pathlib import Path
from typing import Any

from astaa_deft.engine.bus.process_launch import die_with_parent, guarded_fork, start
from astaa_deft.engine.bus.processes import process_running, python_module
from astaa_deft.io.inputfile import SPEC, read_input

REAP_SECONDS = 0.5
FORK_TIMEOUT = 60.0


class Zygote:
    """The campaign's side: start the template process, ask it for case processes."""

    def __init__(self, spec: str, dictionaries: list[str]):
        self._control, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            self.process = start([*python_module("astaa_deft.orchestration.campaign.zygote"), str(theirs.fileno()),
                                  spec, *dictionaries], pass_fds=(theirs.fileno(),))
        finally:
            theirs.close()
        self._lock = threading.Lock()
        self._control.settimeout(FORK_TIMEOUT)  # its start (imports, the spec) included, on a loaded machine
        self._answers = self._control.makefile("r", encoding="utf-8")

    def alive(self) -> bool:
        return self.process.poll() is None

    def fork(self) -> tuple[int, socket.socket]:
        """A new case process: (its pid, the socket to send its payload on and read its outcome from)."""
        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            with self._lock:
                socket.send_fds(self._control, [b"f"], [theirs.fileno()])
                line = self._answers.readline()
        except OSError:  # a timeout included: a late answer would be the next request's, so no more requests
            self.process.kill()
            line = ""
        finally:
            theirs.close()
        if not line.strip().isdigit():
            ours.close()
            raise OSError("the case template process did not fork")
        return int(line), ours

    def close(self) -> None:
        with contextlib.suppress(OSError):  # both: the socket stays open while its file object is
            self._answers.close()
            self._control.close()
        try:
            self.process.wait(timeout=10.0)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait(timeout=5.0)


def stop_group(pid: int, grace: float) -> None:
    """Stop a forked case's process group (not our child: wait until it is gone, then kill)."""
    import time

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


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    control = socket.socket(fileno=int(argv[0]))
    spec, dictionaries = argv[1], argv[2:]
    from astaa_deft.model.errors import InputError
    from astaa_deft.engine.intercept.dictionary import load_dictionary
    from astaa_deft.engine.spec.loader import load_spec
    from astaa_deft.orchestration.campaign import worker

    from astaa_deft.engine.spec.loader import load_spec_text

    preloaded: Any = None
    for_recorder: Any = None
    with contextlib.suppress(InputError):  # a bad spec is each case's error to report (execute loads it again)
        preloaded = (spec, dictionaries, load_spec(Path(spec)), load_dictionary([Path(p) for p in dictionaries]))
    with contextlib.suppress(Exception):  # the recorder's own parse of the text (see forked.py)
        text = read_input(spec, SPEC).decode("utf-8")
        for_recorder = (text, load_spec_text(text, name=Path(spec).name))
    zygote = os.getpid()
    while True:
        ready, _, _ = select.select([control], [], [], REAP_SECONDS)
        _reap()
        if not ready:
            continue
        try:
            _, fds, _, _ = socket.recv_fds(control, 1, 1)
        except OSError:
            break
        if not fds:  # the campaign closed its end
            break
        pid = guarded_fork("a case process")  # this process runs one thread and no Zenoh session
        if pid == 0:
            control.close()
            _case(fds[0], spec, preloaded, for_recorder, worker, parent=zygote)  # never returns
        os.close(fds[0])
        control.sendall(f"{pid}\n".encode())
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


def _case(fd: int, spec: str, preloaded: Any, for_recorder: Any, worker: Any, *, parent: int) -> None:
    """One case in a forked child: its recorder forked ahead, payload in, outcome out (module doc)."""
    code = 1
    try:
        os.setsid()
        die_with_parent(parent)
        conn = socket.socket(fileno=fd)
        recorder = worker.recorder_ahead(Path(spec), for_recorder)
        with conn.makefile("rb") as stream:
            payload = json.loads(stream.read())
        run_dir = Path(payload["run_dir"])
        run_dir.mkdir(parents=True, exist_ok=True)
        err = os.open(run_dir / "case.log", os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        os.dup2(err, 2)
        os.close(err)
        sys.stderr = open(2, "w", encoding="utf-8", closefd=False)  # noqa: SIM115 - the process's own stream
        try:
            body = worker.execute(payload, preloaded, recorder)
        finally:
            worker.release_warm_recorder(recorder)
        conn.sendall((json.dumps(body, default=str) + "\n").encode())
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
