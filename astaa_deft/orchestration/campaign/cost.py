"""What one run costs the machine: CPU seconds and resident memory of every process of the run.

CPU is read the way the template process accounts its cases (zygote.py):
``getrusage`` of the case process itself plus its reaped children — the
recorder, every module (the launcher waits for each) and whatever those
reaped in turn. A case process forked from the template starts its counters
at zero. Resident memory has no such sum, so a sampler thread adds up the
RSS of the case process and all its descendants (from ``/proc``) while the
run goes on and keeps the peak, and reads every thread's scheduler times
to tell the CPU a CPU-bound thread waited for (:class:`WantedCpu`).
"""

from __future__ import annotations

import contextlib
import os
import resource
import threading
import time
from pathlib import Path

RSS_EVERY_SECONDS = 0.5
_PAGE_MB = os.sysconf("SC_PAGE_SIZE") / (1024 * 1024) if hasattr(os, "sysconf") else 4096 / (1024 * 1024)


def cpu_seconds() -> float:
    """User + system CPU seconds of this process and of every child it has reaped so far."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def tree_pids(root: int) -> list[int]:
    """``root`` and all its descendants (from /proc; those that exit meanwhile are left out)."""
    children: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir() if Path("/proc").is_dir() else ():
        if not entry.name.isdigit():
            continue
        try:
            ppid = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
        except (OSError, IndexError, ValueError):
            continue  # gone meanwhile
        children.setdefault(ppid, []).append(int(entry.name))
    out, todo = [], [root]
    while todo:
        pid = todo.pop()
        out.append(pid)
        todo.extend(children.get(pid, ()))
    return out


def rss_mb(pids: list[int]) -> float:
    """Summed resident memory (MiB) of these processes; 0 for one /proc cannot tell about."""
    total = 0.0
    for pid in pids:
        with contextlib.suppress(OSError, IndexError, ValueError):  # gone meanwhile
            total += int(Path(f"/proc/{pid}/statm").read_text().split()[1]) * _PAGE_MB
    return total


def task_schedstats(pids: list[int]) -> dict[tuple[int, int], tuple[int, int]]:
    """(pid, thread id) → (ns on a CPU, ns waiting for one) of every thread of these processes."""
    out: dict[tuple[int, int], tuple[int, int]] = {}
    for pid in pids:
        with contextlib.suppress(OSError):
            for task in Path(f"/proc/{pid}/task").iterdir():
                with contextlib.suppress(OSError, IndexError, ValueError):
                    run, wait = (Path(task, "schedstat").read_text().split() + ["0", "0"])[:2]
                    out[(pid, int(task.name))] = (int(run), int(wait))
    return out


BUSY_SHARE = 0.9  # a thread runnable (on a CPU or waiting for one) this share of the time is CPU-bound


class WantedCpu:
    """The CPU that CPU-bound threads waited for: what a run would use on a machine with a core to spare.

    A thread runnable nearly all the time (a planner's search, a busy loop) gets less than the core it
    wants on a busy machine, so its CPU time understates the run's demand: its time in the run queue is
    added. A thread that mostly sleeps also waits a little at each wake-up; that is latency, not demand,
    so only CPU-bound threads count.
    """

    def __init__(self) -> None:
        self.first: dict[tuple[int, int], tuple[float, int, int]] = {}
        self.last: dict[tuple[int, int], tuple[float, int, int]] = {}

    def sample(self, pids: list[int]) -> None:
        now = time.monotonic()
        for task, (run, wait) in task_schedstats(pids).items():
            self.first.setdefault(task, (now, run, wait))
            self.last[task] = (now, run, wait)

    def waited_seconds(self) -> float:
        extra = 0.0
        for task, (t1, run1, wait1) in self.last.items():
            t0, run0, wait0 = self.first[task]
            span = t1 - t0
            runnable = (run1 - run0 + wait1 - wait0) / 1e9
            if span >= 1.0 and runnable >= BUSY_SHARE * span:
                extra += (wait1 - wait0) / 1e9
        return extra


def available_memory_mb() -> float | None:
    """MemAvailable of the machine (MiB), None where /proc/meminfo does not say."""
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) / 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


class RunCost:
    """Measures one run from :meth:`start` to :meth:`stop`: CPU seconds, wall seconds, peak tree RSS (MiB),
    CPU seconds waited for.

    ``sample_rss``: sample the process tree (memory, scheduler times: a
    /proc walk every half second) — worth it in the clean runs that
    calibrate a campaign.
    """

    def __init__(self, sample_rss: bool):
        self.sample_rss = sample_rss
        self.cpu = 0.0
        self.waited = 0.0  # CPU seconds CPU-bound threads waited for (sampled runs only; :class:`WantedCpu`)
        self._wanted = WantedCpu()
        self.wall = 0.0
        self.rss_mb = 0.0
        self._cpu0 = 0.0
        self._t0 = 0.0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> None:
        self._cpu0, self._t0 = cpu_seconds(), time.monotonic()
        if self.sample_rss:
            self._thread = threading.Thread(target=self._sample, name="run-rss", daemon=True)
            self._thread.start()

    def _sample(self) -> None:
        me = os.getpid()
        while not self._stop.wait(RSS_EVERY_SECONDS):
            pids = tree_pids(me)
            self.rss_mb = max(self.rss_mb, rss_mb(pids))
            self._wanted.sample(pids)

    def stop(self) -> None:
        """Call after the run's processes were reaped (their CPU counts only then)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        self.cpu = max(0.0, cpu_seconds() - self._cpu0)
        self.wall = time.monotonic() - self._t0
        self.waited = self._wanted.waited_seconds()
