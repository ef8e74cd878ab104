"""The reaper: ends a run's process groups if the tool itself dies.

The launcher starts one reaper per run and writes it the id of each process
group it starts, one per line. On a normal stop the launcher has already
ended them and writes ``done``; if instead the reaper's input closes without
``done`` (the tool was killed, even with SIGKILL), it signals exactly those
groups: SIGTERM, then SIGKILL after a grace period. A module's own children
live in its group, so they go too.
"""

from __future__ import annotations

import os
import signal
import sys
import time
import contextlib

GRACE_SECONDS = 3.0


def main() -> int:
    # Ignore the terminal's Ctrl-C: the tool handles it and then tells us "done".
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    groups: list[int] = []
    for line in sys.stdin:
        line = line.strip()
        if line == "done":
            return 0
        if line.isdigit():
            groups.append(int(line))
    _end(groups)
    return 0


def _end(groups: list[int]) -> None:
    for sig in (signal.SIGTERM, signal.SIGKILL):
        for pgid in groups:
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(pgid, sig)
        if sig == signal.SIGTERM:
            deadline = time.monotonic() + GRACE_SECONDS
            while time.monotonic() < deadline and any(_group_alive(g) for g in groups):
                time.sleep(0.05)


def _group_alive(pgid: int) -> bool:
    try:
        os.killpg(pgid, 0)
        return True
    except (ProcessLookupError, PermissionError):
        return False


if __name__ == "__main__":
    sys.exit(main())
