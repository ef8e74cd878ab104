"""The stack's revision: ``git describe`` of the folder the spec's ``source:`` names.

Runs ``git`` (a program the user has, on a folder the user's spec names),
never anything a journal or a log names.
"""

from __future__ import annotations

import subprocess
from pathlib import Path

from astaa_deft.engine.bus import process_launch
from astaa_deft.model.errors import InputError, Problem

GIT_TIMEOUT = 60.0


def git(checkout: Path, *args: str, what: str = "git") -> str:
    """``git -C checkout ARGS``'s output (stripped); InputError naming the folder when it fails."""
    try:
        done = process_launch.run(["git", "-C", str(checkout), *args], timeout=GIT_TIMEOUT)
    except OSError as exc:
        raise InputError(Problem(str(checkout), None, None, f"cannot run git: {exc}",
                                 "install git, or give --label")) from None
    except subprocess.TimeoutExpired:
        raise InputError(Problem(str(checkout), None, None, f"{what}: git did not answer in {GIT_TIMEOUT:.0f} s",
                                 "check the checkout (a lock file, a network remote)")) from None
    if done.returncode != 0:
        error = (done.stderr or done.stdout or "").strip().splitlines()[-1:] or [""]
        raise InputError(Problem(str(checkout), None, None, f"{what} failed: {error[0][:300]}",
                                 "name the stack's git checkout in the spec's 'source:', or give --label"))
    return str(done.stdout).strip()


def describe(checkout: Path) -> str:
    """``git describe --always --dirty --tags`` of the checkout; InputError when it is no git checkout."""
    return git(checkout, "describe", "--always", "--dirty", "--tags", what="git describe")
