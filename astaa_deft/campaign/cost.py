"""What one run costs the machine: CPU seconds and resident memory of every process of the run.

CPU is read the way the template process accounts its cases (zygote.py):
``getrusage`` of the case process itself plus its reaped children — the
recorder, every module (the launcher waits for each) and whatever those
reaped in turn. A case process forked from the template starts its counters
at zero. Resident memory has no such sum, so a sampler thread adds up the
RSS of the case process and all its descendants (from ``/proc``) while the
run goes on and keeps the peak.
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


def tree_rss_mb(root: int) -> float:
    """Summed resident memory (MiB) of ``root`` and all its descendants; 0 where /proc cannot tell."""
    children: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir() if Path("/proc").is_dir() else ():
        if not entry.name.isdigit():
            continue
        try:
            ppid = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
        except (OSError, IndexError, ValueError):
            continue  # gone meanwhile
        children.setdefault(ppid, []).append(int(entry.name))
    total, todo = 0.0, [root]
    while todo:
        pid = todo.pop()
        with contextlib.suppress(OSError, IndexError, ValueError):  # gone meanwhile
            total += int(Path(f"/proc/{pid}/statm").read_text().split()[1]) * _PAGE_MB
        todo.extend(children.get(pid, ()))
    return total


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
    """Measures one run from :meth:`start` to :meth:`stop`: CPU seconds, wall seconds, peak tree RSS (MiB).

    ``sample_rss``: sample the process tree's memory (a /proc walk every
    half second) — worth it in the clean runs that calibrate a campaign.
    """

    def __init__(self, sample_rss: bool):
        self.sample_rss = sample_rss
        self.cpu = 0.0
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
            self.rss_mb = max(self.rss_mb, tree_rss_mb(me))

    def stop(self) -> None:
        """Call after the run's processes were reaped (their CPU counts only then)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        self.cpu = max(0.0, cpu_seconds() - self._cpu0)
        self.wall = time.monotonic() - self._t0
