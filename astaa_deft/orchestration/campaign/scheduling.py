"""The campaign's scheduling: how many runs at once, the pool, and submitting a case.

Runs at once are calibrated in the baseline (a run alone, then clean runs at the picked concurrency
until their timing stops drifting) and watched while the hunt goes on (the machine's load, the
unmutated twins' timing). A part of :class:`~.campaign.Campaign` (its state:
:class:`~.parts.CampaignParts`).
"""

from __future__ import annotations

import os
import time
from pathlib import Path

from astaa_deft.orchestration.campaign.baseline import learning_shutdown_delays
from astaa_deft.orchestration.campaign.calibration import (
    CEILING_LOAD_DROP, DRIFT_TOLERANCE, MachineNow, RunShare, drift, fewer_after_drift, overloaded, raised, run_share,
    workers_for,
)
from astaa_deft.orchestration.campaign.cost import available_memory_mb
from astaa_deft.orchestration.campaign.payload import CasePayload, CasePool
from astaa_deft.orchestration.journal.rows import CaseRow
from astaa_deft.orchestration.journal.model import (
    BASELINE, CONTROL, MUTATED, RERUN, CaseOutcome, CaseStatus, PlannedCase,
)
from astaa_deft.orchestration.campaign.parts import CampaignParts


MAX_CALIBRATION_CHECKS = 3  # batches of clean runs at a concurrency before the campaign takes what it has
MAX_WORKERS_PER_CORE = 4  # the local pool's threads: calibration picks at most this many runs a core
SETTLE_LOAD_SECONDS = 60.0  # after a change of runs at once, the 1-min load average needs this long to show it


class Scheduling(CampaignParts):
    """Runs at once (calibrated, then watched), the pool, a case submitted."""

    def _pool(self) -> CasePool:
        from astaa_deft.orchestration.campaign.executors import DaskPool, LocalPool

        if self.config.cluster:
            pool = DaskPool(self.config.cluster, self.workers)
            if self.config.workers is None and pool.workers != self.workers:  # workers joined or left since
                self.say(f"runs at once: {pool.workers}, the cluster's workers now")
                self.workers = pool.workers
            return pool
        # Threads for as many runs as calibration may pick; the campaign keeps self.workers of them busy.
        return LocalPool(self.workers if not self.calibrated else self._most_workers())

    def _most_workers(self) -> int:
        return max(self.workers, MAX_WORKERS_PER_CORE * self.cores)

    def _run_pending_baseline(self, pool: CasePool, at_once: int | None = None, last: int | None = None) -> None:
        """Run the planned baseline runs (numbered up to ``last``), ``at_once`` (default: the campaign's) at a time."""
        queue = [self._planned(c) for c in self.journal.pending(BASELINE) if last is None or c.number <= last]
        limit = at_once or self.workers
        while queue or pool.pending():
            while queue and pool.pending() < limit:
                self._submit(pool, queue.pop(0))
            for case_id, outcome in pool.done(timeout=0.5):
                self._finished(case_id, outcome)
            self._progress()

    def _solo_runs(self) -> dict[str, CaseOutcome]:
        """The first clean run of each param value, run alone (calibrated campaigns): the timing reference."""
        if not self.journal.meta().calibrated:
            return {}
        solo: dict[str, CaseOutcome] = {}
        for row in self.journal.cases(BASELINE)[:len(self.grid)]:
            outcome = self.journal.outcome(row)
            if outcome is not None and outcome.status == CaseStatus.DONE:
                solo[row.params_key] = outcome
        return solo

    def _calibrate_workers(self, pool: CasePool, per_value: int) -> None:
        """Runs at once from what a run costs alone, checked by clean runs at that concurrency (calibration.py):
        one run of each param value alone, then the rest of the baseline (at least as many runs as go at
        once) at that concurrency, fewer at once while their timing drifts from the solo runs'."""
        alone = len(self.grid)
        self.workers = 1  # the solo runs
        self._run_pending_baseline(pool, at_once=1, last=alone)
        self.journal.set_meta(calibrated=True)
        solo = self._solo_runs()
        share = run_share(list(solo.values()))
        if share is None:  # nothing ran alone to its end: the estimate stands, the baseline goes on
            self._run_pending_baseline(pool)
            self.journal.set_meta(workers=self.workers)
            return
        other = max(0.0, os.getloadavg()[0] - share.cores)  # the solo run's own part of the load apart
        self._concurrency(workers_for(share, self.cores, available_memory_mb(), most=self._most_workers(),
                                      other_load=other),
                          f"one run takes {share.describe()}; {self.cores} core(s), load {other:.1f} from other"
                          f" work, with headroom")
        first, last = alone + 1, max(per_value * alone, alone + self.workers)
        for _check in range(MAX_CALIBRATION_CHECKS):
            self._plan_baseline(last)
            self._run_pending_baseline(pool)
            loaded = [(r, self.journal.outcome(r)) for r in self.journal.cases(BASELINE)
                      if first <= r.number <= last and r.status == CaseStatus.DONE]
            drifts = [drift(solo[r.params_key], o) for r, o in loaded if o is not None and r.params_key in solo]
            worst = max(drifts, key=lambda d: d.ratio, default=None)
            if worst is None:
                break
            if not worst.drifted:
                self.journal.note("concurrency", f"{self.workers} at once: timing within ×{DRIFT_TOLERANCE:g} of"
                                                 f" a run alone (worst: {worst.detail}, ×{worst.ratio:.2f})")
                break
            if self.workers == 1:  # alone already: the drift is the machine's (other load), nothing to lower
                self._concurrency(1, f"timing drifted even one at a time: {worst.detail}, ×{worst.ratio:.1f}")
                break
            overloaded_runs = [*self.journal.meta().overloaded_runs, *(r.case_id for r, _ in loaded)]
            self.journal.set_meta(overloaded_runs=overloaded_runs)
            self._drifted(self.workers)
            self._concurrency(fewer_after_drift(self.workers, worst),
                              f"timing drifted at {self.workers} at once: {worst.detail}, ×{worst.ratio:.1f}")
            if self.workers == 1:
                break
            first, last = last + 1, last + self.workers
        self.journal.set_meta(workers=self.workers)

    def _concurrency(self, workers: int, why: str) -> None:
        """Change the runs at once, and say why (on the terminal and in the journal)."""
        before, self.workers = self.workers, max(1, workers)
        self._last_change = time.monotonic()
        text = f"runs at once: {self.workers}" + (f" (was {before})" if before != self.workers else "") + f": {why}"
        self.journal.note("concurrency", text)
        self.say(text)

    def _busy(self) -> int:
        """Worker slots taken: cases in flight and minimisations running."""
        return len(self._running_cases) + len(self._minimising)

    def _submit(self, pool: CasePool, case: PlannedCase) -> None:
        horizon = self.clean_horizon if case.kind in (BASELINE, CONTROL) else self.horizon
        payload = CasePayload(spec=str(self.config.spec_path.resolve()), case=case,
                              run_dir=str(self.case_dir(case.case_id)), horizon=horizon,
                              dictionaries=tuple(str(p.resolve()) for p in self.config.dictionaries),
                              settle=self.config.settle if case.kind in (MUTATED, RERUN) else None,
                              known=tuple(sorted(self.known)),
                              shutdown_delays=learning_shutdown_delays(self.spec) if case.kind == BASELINE
                              else dict(self.shutdown_delays))
        self.journal.started(case.case_id)
        self._running_cases.add(case.case_id)
        pool.submit(case.case_id, payload.to_json())

    def case_dir(self, case_id: str) -> Path:
        return (self.config.out / "cases" / case_id).resolve()

    # -- load: fewer runs at once when the machine or the SUT's timing says so -------------------------------
    def _watch_load(self) -> None:
        """Fewer runs at once when the machine is overloaded; more when the other load fell and more fit (the
        twins' timing at the new count is checked as always: drift lowers it again). One step a minute."""
        if not self.calibrated or time.monotonic() - self._last_change < SETTLE_LOAD_SECONDS:
            return
        load1 = os.getloadavg()[0]
        if overloaded(load1, self.cores):
            if self.workers > 1:
                self._concurrency(self.workers - 1, f"load {load1:.1f} above {self.cores} core(s)")
            return
        share = self._share()
        if share is None:
            return
        ours = self._busy() * share.cores
        if self._ceiling is not None and load1 - ours < self._ceiling_other - CEILING_LOAD_DROP:
            self._ceiling = None  # the machine has more room than when the timing drifted
        machine = MachineNow(cores=self.cores, memory_mb=available_memory_mb(), load1=load1, ours=ours)
        more = raised(share, machine, most=self._most_workers(), workers=self.workers, ceiling=self._ceiling)
        if more.workers > self.workers:
            self._concurrency(more.workers, f"{more.why}; no unmutated twin's timing drifted at {self.workers}")

    def _share(self) -> RunShare | None:
        """What one run takes (the solo runs of the baseline), None when none was measured."""
        return run_share(list(self._solo.values()))

    def _drifted(self, workers: int) -> None:
        """Timing drifted at ``workers`` runs at once: not raised to that again while the other load stays."""
        share = self._share()
        ours = self._busy() * share.cores if share is not None else 0.0
        self._ceiling = workers if self._ceiling is None else min(self._ceiling, workers)
        self._ceiling_other = max(0.0, os.getloadavg()[0] - ours)

    def _watch_timing(self, row: CaseRow, outcome: CaseOutcome) -> None:
        """A control run is a clean run at the campaign's concurrency: its timing against the run alone."""
        solo = self._solo.get(row.params_key)
        if (not self.calibrated or solo is None or outcome.status != CaseStatus.DONE or self.workers == 1
                or time.monotonic() - self._last_change < SETTLE_LOAD_SECONDS):
            return
        found = drift(solo, outcome)
        if found.drifted:
            self._drifted(self.workers)
            self._concurrency(self.workers - 1, f"timing drifted in clean run {row.case_id}: {found.detail},"
                                                f" ×{found.ratio:.1f}")

