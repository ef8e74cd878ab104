"""How many runs at once the machine holds without changing the SUT's timing (pure: numbers in, numbers out).

A run's cost is measured, not guessed: the clean baseline runs report the
CPU seconds and peak memory of every process of the run (:mod:`.cost`).
The runs at once are the cores (with headroom) over one run's share of a
core, bounded by memory. Then clean runs *at that concurrency* are compared
with a run alone: when a channel's longest gap or its rate gets clearly
worse, the timing the SUT is tested under is not its own (a deadline miss
would be the campaign's doing), so fewer runs at once.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from astaa_deft.orchestration.journal.model import CaseOutcome

CORE_HEADROOM = 0.75  # share of the cores the runs may use: the campaign, the OS and jitter need the rest
MEMORY_HEADROOM = 0.5  # share of the available memory the runs may use
DRIFT_TOLERANCE = 1.5  # a channel's gap this many times its solo gap (or rate this many times lower) is drift
GAP_FLOOR_PERIODS = 3.0  # gaps shorter than this many of the channel's periods are jitter, whatever the ratio
GAP_FLOOR_SECONDS = 0.05  # … and shorter than this
MIN_MESSAGES = 5  # a channel with fewer messages in the solo run says nothing about timing


@dataclass(frozen=True)
class RunShare:
    """What one run takes of the machine: cores on average over its wall time, peak memory (MiB)."""

    cores: float
    rss_mb: float
    runs: int  # how many runs it was measured on

    def describe(self) -> str:
        return f"{self.cores:.2f} core and {self.rss_mb:.0f} MiB a run (measured on {self.runs} clean run(s))"


@dataclass(frozen=True)
class Drift:
    """How much worse a run's timing was than its solo run: the worst channel and its ratio (1: the same)."""

    ratio: float
    channel: str | None
    detail: str

    @property
    def drifted(self) -> bool:
        return self.ratio > DRIFT_TOLERANCE


def run_share(outcomes: list[CaseOutcome]) -> RunShare | None:
    """The largest share measured over these runs (None: none measured): a run that happens to cost more
    is what the concurrency must hold. Its CPU and the CPU its CPU-bound threads waited for (a busy
    machine gives a search less than the core it wants)."""
    measured = [o for o in outcomes if o.status == "done" and o.wall > 0 and o.cpu > 0]
    if not measured:
        return None
    return RunShare(max((o.cpu + o.cpu_waited) / o.wall for o in measured), max(o.rss_mb for o in measured),
                    len(measured))


def workers_for(share: RunShare, cores: int, memory_mb: float | None, most: int | None = None,
                *, other_load: float = 0.0) -> int:
    """Runs at once that fit the cores other work leaves (``other_load``: runnable tasks not ours), with
    headroom, and the available memory, at most ``most``; at least 1.

    On a busy machine a CPU-bound module gets less than the core it wants, so its measured share is low;
    counting the others' load keeps such a stack from being run many at once where no core is free."""
    free = max(0.0, cores - other_load) * CORE_HEADROOM
    by_cpu = math.floor(free / max(share.cores, 0.01))
    by_memory = math.floor(memory_mb * MEMORY_HEADROOM / share.rss_mb) if memory_mb and share.rss_mb > 0 else by_cpu
    return max(1, min(by_cpu, by_memory, most if most is not None else by_cpu))


def drift(solo: CaseOutcome, loaded: CaseOutcome) -> Drift:
    """How much worse ``loaded``'s channel timing was than ``solo``'s (same params): longest gaps and rates."""
    worst = Drift(1.0, None, "same timing")
    for channel, alone in solo.timing.items():
        there = loaded.timing.get(channel)
        if there is None or alone.count < MIN_MESSAGES:
            continue
        period = 1.0 / alone.rate if alone.rate else 0.0
        floor = max(GAP_FLOOR_PERIODS * period, GAP_FLOOR_SECONDS)
        gap_ratio = max(there.max_gap, floor) / max(alone.max_gap, floor)
        rate_ratio = alone.rate / there.rate if there.rate else math.inf
        if gap_ratio > worst.ratio:
            worst = Drift(gap_ratio, channel, f"'{channel}' longest gap {there.max_gap:.2f} s"
                                              f" (alone {alone.max_gap:.2f} s)")
        if rate_ratio > worst.ratio:
            worst = Drift(rate_ratio, channel, f"'{channel}' {there.rate:.1f} msg/s (alone {alone.rate:.1f})")
    return worst


def fewer_after_drift(workers: int, found: Drift) -> int:
    """Runs at once after timing drifted at ``workers``: in proportion to the drift, at least one fewer."""
    return max(1, min(workers - 1, math.floor(workers / found.ratio)))


OVERLOAD_FACTOR = 1.5  # load per core that alone means fewer runs at once (below it, the twins' timing decides)


def overloaded(load1: float, cores: int) -> bool:
    """The machine's one-minute load is well above its cores: runs wait for a core, and their timing shows it.

    A machine in full use has a load near its cores that swings above them
    (on the demo, two runs at once on two cores: 2.0–2.4, with the twins'
    timing unchanged); only a load of ``OVERLOAD_FACTOR`` × cores backs off
    on its own, any real drift shows in the unmutated twins' timing first.
    """
    return load1 > OVERLOAD_FACTOR * cores


CEILING_LOAD_DROP = 1.0  # the other load this much lower than when timing drifted: the drift's limit is lifted


@dataclass(frozen=True)
class Raise:
    """Whether more runs may go at once now: the count, the other load it was judged on, and why (or why not)."""

    workers: int
    other_load: float
    why: str


@dataclass(frozen=True, kw_only=True)
class MachineNow:
    """The machine as a raise judges it: its cores, its available memory (None: not known), its one-minute
    load, and ``ours``, the part of that load the campaign's own runs make (the runs in flight × a run's
    share); the rest is other work's."""

    cores: int
    memory_mb: float | None
    load1: float
    ours: float


def raised(share: RunShare, machine: MachineNow, *, most: int, workers: int, ceiling: int | None) -> Raise:
    """One more run at once when the cores the other work leaves now hold more runs than go at once.

    ``ceiling``: a count at which the runs' timing drifted (None: none) —
    never reached again while the other load has not fallen by CEILING_LOAD_DROP since (the caller lifts it).
    One step at a time: the twins' timing at the new count decides the next (as when lowering).
    """
    cores, load1, ours = machine.cores, machine.load1, machine.ours
    other = max(0.0, load1 - ours)
    fit = workers_for(share, cores, machine.memory_mb, most=most, other_load=other)
    if ceiling is not None:
        fit = min(fit, ceiling - 1)
    if fit <= workers:
        return Raise(workers, other, f"{fit} fit{'s' if fit == 1 else ''} beside other load {other:.1f}")
    return Raise(workers + 1, other, f"the other load fell to {other:.1f} (load {load1:.1f}, the campaign's runs"
                                     f" {ours:.1f}) on {cores} core(s): {fit} runs of {share.cores:.2f} core fit")
