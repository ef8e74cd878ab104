"""The stack's revision: ``git describe`` of the folder the spec's ``source:`` names.

Runs ``git`` (a program the user has, on a folder the user's spec names),
never anything a journal or a log names — and never a command the checkout's
own configuration names: a checkout may be someone else's (a stack fetched
to reproduce a bug), and its ``.git/config`` can name programs git runs by
itself (``core.fsmonitor`` on any index refresh, hooks on checkout, clean
and smudge filters, a pager). Every call turns those off on its command
line (``-c``, which overrides the repository's config), for every filter
driver any config level defines.
"""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

from astaa_deft.engine.bus import process_launch
from astaa_deft.model.errors import InputError, Problem

GIT_TIMEOUT = 60.0


# Settings that make git run a program of the configuration's choosing, turned off.
QUIET_CONFIG = ("core.fsmonitor=false", "core.hooksPath=/dev/null", "core.pager=cat", "core.untrackedCache=false",
                "diff.external=", "core.sshCommand=false", "protocol.allow=never")
_FILTER_SETTINGS = ("clean", "smudge", "process")


def _quiet_args(checkout: Path) -> list[str]:
    """``-c`` options turning off every config-named program (module doc), filters included: their driver names
    are read from git's config (reading config runs nothing)."""
    args = [item for setting in QUIET_CONFIG for item in ("-c", setting)]
    try:
        listed = process_launch.run(["git", "-C", str(checkout), *args, "config", "--name-only", "--list"],
                                    timeout=GIT_TIMEOUT, env=_env())
    except (OSError, subprocess.TimeoutExpired):
        return args  # the call itself will say what is wrong
    drivers = {name.split(".")[1] for name in (listed.stdout or "").split()
               if name.startswith("filter.") and name.count(".") >= 2}
    for driver in sorted(drivers):
        args += [item for setting in _FILTER_SETTINGS for item in ("-c", f"filter.{driver}.{setting}=")]
        args += ["-c", f"filter.{driver}.required=false"]
    return args


_QUIET_ENV = {"GIT_PAGER": "cat", "GIT_TERMINAL_PROMPT": "0", "GIT_OPTIONAL_LOCKS": "0"}


def _env() -> dict[str, str]:
    return {**os.environ, **_QUIET_ENV}


def git(checkout: Path, *args: str, what: str = "git") -> str:
    """``git -C checkout ARGS``'s output (stripped), with the checkout's config-named programs off (module doc);
    InputError naming the folder when it fails."""
    try:
        done = process_launch.run(["git", "-C", str(checkout), *_quiet_args(checkout), *args], timeout=GIT_TIMEOUT,
                                  env=_env())
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
