"""Campaign progress: a live bar on a terminal (rich), plain lines otherwise."""

from __future__ import annotations

import os
import sys
import time
from dataclasses import dataclass
from typing import TextIO

from astaa_deft.orchestration.journal.rows import MUTATED_VALUE
from astaa_deft.orchestration.journal.journal import Journal
from astaa_deft.orchestration.journal.model import MUTATED

PLAIN_EVERY_SECONDS = 10.0


@dataclass(frozen=True, kw_only=True)
class Snapshot:
    done: int
    planned: int | None
    failures: int
    buckets: int
    running: int
    elapsed: float
    bugs: int = 0  # buckets confirmed as bugs
    at_once: int | None = None  # runs the campaign keeps going at once now
    load: float | None = None  # the machine's 1-min load average
    cores: int | None = None

    @property
    def rate_per_min(self) -> float:
        return 60.0 * self.done / self.elapsed if self.elapsed > 0 else 0.0

    def line(self) -> str:
        total = f"/{self.planned}" if self.planned else ""
        eta = ""
        if self.planned and self.done and self.rate_per_min > 0:
            eta = f", ETA {max(0.0, (self.planned - self.done) / self.rate_per_min):.1f} min"
        return (f"cases {self.done}{total} ({self.running} running), failures {self.failures}, "
                f"buckets {self.buckets} ({self.bugs} bug), {self.rate_per_min:.1f} cases/min{eta}{self.machine()}")

    def machine(self) -> str:
        """How hard the machine works: runs at once, load over cores (empty when not known)."""
        parts = []
        if self.at_once is not None:
            parts.append(f"{self.at_once} at once")
        if self.load is not None:
            parts.append(f"load {self.load:.1f}" + (f"/{self.cores} cores" if self.cores else ""))
        return ", " + ", ".join(parts) if parts else ""


def snapshot(journal: Journal, planned: int | None, elapsed: float, at_once: int | None = None) -> Snapshot:
    counts = journal.counts()
    # generated cases against the plan; baseline runs and re-runs are extra work, shown as running
    done = sum(v for k, v in counts.items() if k.split(":")[0] == MUTATED and k.split(":")[1] in ("done", "error"))
    running = sum(v for k, v in counts.items() if k.endswith(":running"))
    failures = journal.db.execute("SELECT COUNT(*) FROM cases WHERE kind=? AND verdict NOT IN ('Pass', '?')",
                                  (MUTATED,)).fetchone()[0]
    live = journal.buckets(include_merged=False)
    # A bucket the fault alone causes (blamed on the mutated value itself) is no bug of the stack (standing.py).
    blames = journal.blames()
    alone = {name for name, blame in blames.items() if blame.how == MUTATED_VALUE}
    bugs = sum(1 for b in live if b.is_bug and b.bucket not in alone)
    return Snapshot(done=done, planned=planned, failures=failures, buckets=len(live), running=running, elapsed=elapsed,
                    bugs=bugs, at_once=at_once, load=os.getloadavg()[0], cores=os.cpu_count())


class Progress:
    def __init__(self, journal: Journal, planned: int | None, stream: TextIO = sys.stderr):
        self.journal = journal
        self.planned = planned
        self.stream = stream
        self.started = time.monotonic()
        self.last_plain = 0.0
        self.live = None
        if stream.isatty():
            from rich.console import Console
            from rich.progress import BarColumn, MofNCompleteColumn, Progress as Bar, TextColumn, TimeRemainingColumn

            self.bar = Bar(TextColumn("fuzz"), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn(),
                           TextColumn("{task.description}"), console=Console(file=stream), transient=False)
            self.task = self.bar.add_task("", total=planned)
            self.bar.start()
            self.live = self.bar

    def say(self, text: str) -> None:
        if self.live is not None:
            self.bar.console.print(text)
        else:
            print(text, file=self.stream, flush=True)

    def __call__(self, at_once: int | None = None) -> None:
        """Show the campaign's progress now (the bar) or every PLAIN_EVERY_SECONDS (plain lines); ``at_once``:
        its runs at once."""
        snap = snapshot(self.journal, self.planned, time.monotonic() - self.started, at_once)
        if self.live is not None:
            self.bar.update(self.task, completed=snap.done,
                            description=f"failures {snap.failures} · buckets {snap.buckets} ({snap.bugs} bug) · "
                                        f"{snap.rate_per_min:.1f}/min{snap.machine().replace(', ', ' · ')}")
        elif time.monotonic() - self.last_plain >= PLAIN_EVERY_SECONDS:
            self.last_plain = time.monotonic()
            print(snap.line(), file=self.stream, flush=True)

    def close(self) -> None:
        if self.live is not None:
            self.bar.stop()
            self.live = None
