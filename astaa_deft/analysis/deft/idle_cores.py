"""How many cores are idle right now: the forked search's parallelism (``extract --jobs`` by default).

Measured from the CPUs' idle time in /proc/stat between two samples, our own
processes' CPU time counted as idle (they are about to search, not to read or
step): the first sample is taken when the extraction starts, the second only
when a search first runs two candidates at once (``extract``'s ``jobs`` as a
callable, asked by the forked search: an extraction whose outputs never need
two at once — a per-trigger replay, a cheap module whose first candidates are
right — never asks), so the work before is the window and the measure costs
nothing. "Our own" is the line of processes the asking one was forked from
(the caller, the replay's supervisor, the runner): each fork hands its CPU
time down. The
load average — a minute's decaying mean — still counts a recording or a plain
replay that has just ended: it gave one of two idle cores, and 15–17 % longer
extractions on the zoo's expensive members. Where there is no /proc/stat,
the CPUs less the load average.
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass

MIN_WINDOW_S = 0.1  # a shorter window is waited out (10 clock ticks a CPU): another process's work must show

# The CPU seconds of the processes this one was forked from, each up to its fork (0 in a process not forked
# here): a sample taken in a forked process counts their time since the first sample as its own.
_inherited_s = 0.0
_handed_down_s = 0.0


def _own_seconds() -> float:
    own = os.times()
    return _inherited_s + own.user + own.system


def _before_fork() -> None:
    global _handed_down_s
    _handed_down_s = _own_seconds()


def _in_child() -> None:
    global _inherited_s
    _inherited_s = _handed_down_s


if hasattr(os, "register_at_fork"):
    os.register_at_fork(before=_before_fork, after_in_child=_in_child)


@dataclass(frozen=True)
class CpuSample:
    """The machine's idle and total CPU time (clock ticks, all CPUs), our own CPU seconds (this process's and
    those of the processes it was forked from, up to each fork), and when."""

    idle_ticks: int
    total_ticks: int
    own_seconds: float
    at: float  # time.monotonic()


def cpu_sample() -> CpuSample | None:
    """Now, from /proc/stat (None where it cannot be read)."""
    try:
        with open("/proc/stat", encoding="ascii") as stat:
            fields = [int(v) for v in stat.readline().split()[1:]]
    except (OSError, ValueError):
        return None
    if len(fields) < 5:
        return None
    # user nice system idle iowait irq softirq steal (guest time is counted in user already)
    return CpuSample(fields[3] + fields[4], sum(fields[:8]), _own_seconds(), time.monotonic())


def idle_share(since: CpuSample) -> float | None:
    """The share of all CPUs' time idle (or used by this process) from ``since`` to now; the window is made
    at least MIN_WINDOW_S long. None where /proc/stat cannot be read."""
    time.sleep(max(0.0, since.at + MIN_WINDOW_S - time.monotonic()))
    now = cpu_sample()
    if now is None or now.total_ticks <= since.total_ticks:
        return None
    own_ticks = (now.own_seconds - since.own_seconds) * os.sysconf("SC_CLK_TCK")
    share = (now.idle_ticks - since.idle_ticks + own_ticks) / (now.total_ticks - since.total_ticks)
    return min(1.0, max(0.0, share))


def idle_cores(since: CpuSample | None = None) -> int:
    """The cores not busy right now (at least one), measured from ``since`` (else over MIN_WINDOW_S from now):
    candidates run in parallel only where that costs the right candidate nothing."""
    cpus = os.cpu_count() or 1
    start = since if since is not None else cpu_sample()
    share = idle_share(start) if start is not None else None
    if share is not None:
        return max(1, math.floor(share * cpus + 0.5))
    return max(1, cpus - math.ceil(os.getloadavg()[0] - 0.5)) if hasattr(os, "getloadavg") else cpus
