"""Small process-control helpers shared by the launcher and the recorder spawn.

Every helper acts on one process or process group the tool started itself,
by its id; nothing here matches processes by name.
"""

from __future__ import annotations

import ctypes
import os
import signal
import subprocess
import sys
from collections import deque
from pathlib import Path
import contextlib

PR_SET_PDEATHSIG = 1

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


def die_with_parent() -> None:
    """preexec_fn: SIGTERM this child when the tool dies, even by SIGKILL (Linux)."""
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGTERM)


def signal_group(process: subprocess.Popen, sig: signal.Signals) -> None:
    """Signal the process group led by `process` (started with start_new_session)."""
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(process.pid, sig)


def stop_process(process: subprocess.Popen, grace: float, sig: signal.Signals = signal.SIGTERM) -> int | None:
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


def tail(path: Path, lines: int = 20) -> str:
    try:
        with open(path, "rb") as fh:
            fh.seek(0, os.SEEK_END)
            fh.seek(max(0, fh.tell() - 16384))
            data = fh.read().decode("utf-8", "replace")
    except OSError:
        return ""
    return "\n".join(deque(data.splitlines(), maxlen=lines))
