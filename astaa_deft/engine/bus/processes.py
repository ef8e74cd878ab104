"""Small process-control helpers: the argv of a helper, and stopping a child the tool started.

Every helper acts on one process or process group the tool started itself
(:mod:`.process_launch` starts them all), by its id; nothing here matches
processes by name.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from collections import deque
from pathlib import Path
from typing import IO, Protocol
import contextlib

# Python 3.10 has no -P: drop the current directory from sys.path by hand, then run the module as -m would.
_RUN_INSTALLED = ("import runpy, sys; sys.path.pop(0); sys.argv[0] = '{m}'; "
                  "runpy.run_module('{m}', run_name='__main__', alter_sys=True)")


def python_module(module: str) -> list[str]:
    """The argv that runs ``module`` of the installed astaa_deft, as ``python -m`` would but safely.

    ``python -m`` puts the current directory first on sys.path, so a helper
    started from inside a checkout (or any folder holding an ``astaa_deft/``)
    would run that code instead of the package the user installed. ``-P``
    (Python >= 3.11) leaves the current directory out; environment variables
    such as ZENOH_CONFIG still reach the helper, which ``-I`` would not allow.
    """
    if sys.version_info >= (3, 11):
        return [sys.executable, "-P", "-m", module]
    return [sys.executable, "-c", _RUN_INSTALLED.format(m=module)]


class RunningProcess(Protocol):
    """What stopping a child takes: a ``subprocess.Popen`` (text or binary) or a forked child (process_launch)."""

    @property
    def pid(self) -> int: ...

    @property
    def returncode(self) -> int | None: ...

    def poll(self) -> int | None: ...

    def wait(self, timeout: float | None = None) -> int: ...


class ChildProcess(RunningProcess, Protocol):
    """A child the tool talks to on its standard streams, in text (a helper, the recorder, a forked child)."""

    @property
    def stdin(self) -> IO[str] | None: ...

    @property
    def stdout(self) -> IO[str] | None: ...


def signal_group(process: RunningProcess, sig: signal.Signals) -> None:
    """Signal the process group led by `process` (every child the tool starts leads its own)."""
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(process.pid, sig)


def stop_process(process: RunningProcess, grace: float, sig: signal.Signals = signal.SIGTERM) -> int | None:
    """Ask one process group to stop, kill it after `grace` seconds; returns the exit code."""
    if process.poll() is None:
        signal_group(process, sig)
        try:
            return process.wait(timeout=grace)
        except subprocess.TimeoutExpired:
            pass
    signal_group(process, signal.SIGKILL)
    try:
        return process.wait(timeout=2.0)
    except subprocess.TimeoutExpired:
        return None


def process_running(pid: int) -> bool:
    """Whether process ``pid`` runs (Linux ``/proc``; a zombie — exited, not yet reaped — does not)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat.rsplit(")", 1)[-1].split()[0] not in ("Z", "X")


def tail(path: Path, lines: int = 20) -> str:
    """The last ``lines`` lines of a text file (its last 16 KiB at most); "" when it cannot be read."""
    try:
        with open(path, "rb") as fh:
            fh.seek(0, os.SEEK_END)
            fh.seek(max(0, fh.tell() - 16384))
            data = fh.read().decode("utf-8", "replace")
    except OSError:
        return ""
    return "\n".join(deque(data.splitlines(), maxlen=lines))
