"""The campaign workflow: baseline, generated cases, buckets, rates, minimisation, report.

Every decision reads from or writes to the journal first, so a campaign
stopped anywhere resumes where it was: finished cases stay finished, the
ones in flight run again, buckets and their re-runs pick up where they were.
"""

from __future__ import annotations

import itertools
import os
import shutil
import threading
import time
from collections.abc import Callable
from concurrent.futures import FIRST_COMPLETED, Future, ThreadPoolExecutor
from concurrent.futures import wait as futures_wait
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TypeVar

from astaa_deft.model.records import Verdict
from astaa_deft.model.errors import AstaaDeftError, InputError, Problem
from astaa_deft.engine.intercept.dictionary import load_dictionary
from astaa_deft.engine.intercept.testcase import TestCase
from astaa_deft.model.sut import Spec
from astaa_deft.engine.spec.params import check_param_values, spread_choices
from astaa_deft.engine.spec.loader import load_spec
from astaa_deft.orchestration.campaign import signature as sig
from astaa_deft.orchestration.campaign.calibration import (
    CEILING_LOAD_DROP, DRIFT_TOLERANCE, RunShare, drift, fewer_after_drift, overloaded, raised, run_share,
    workers_for,
)
from astaa_deft.orchestration.campaign.cost import available_memory_mb
from astaa_deft.orchestration.campaign.blame import BlameUnavailable, blame_logs
from astaa_deft.orchestration.campaign.journal import Bucket, Journal
from astaa_deft.orchestration.campaign.payload import CasePayload, CasePool, read_testcase
from astaa_deft.orchestration.campaign.rows import BlameRow, CampaignMeta, CaseRow, Minimisation, NewBucket
from astaa_deft.orchestration.campaign.known import KnownFinding, judged, known_findings
from astaa_deft.orchestration.campaign.minimiser import MinimiseLimits, Minimised, minimise_run
from astaa_deft.orchestration.campaign.minimiser import summary as minimised_summary
from astaa_deft.orchestration.campaign.module_tests import (
    TestsVerdict, is_crash_bucket, run_module_tests,
)
from astaa_deft.orchestration.campaign.planner_tests import build_in_child as build_planner_tests
from astaa_deft.orchestration.campaign.model import (
    BASELINE, BASELINE_FINDING, BUG, CONFIRMING, CONTROL, FLAKY, MUTATED, RERUN, BucketKind, BucketSignature,
    CaseOutcome, CaseStatus, FailureKey, PlannedCase, TextEnum, Timing,
)
from astaa_deft.orchestration.campaign.strategies import STRATEGIES, Strategy
from astaa_deft.orchestration.verify import records as verification
from astaa_deft.orchestration.verify.history import fixed_buckets

T = TypeVar("T")

DEFAULT_HORIZON = 20.0  # s a run may last when the spec's run: section declares no end at all
CLEAN_RUN_CAP = 600.0  # s a clean run may last when the run: section declares an end but no time_limit
HORIZON_SLACK = 1.25  # a mutated case may run this many times the longest clean run (a misled SUT runs longer)
DEFAULT_BASELINE_RUNS = 2
DEFAULT_RERUNS = 2
DEFAULT_SETTLE = 3.0  # s a mutated case runs on after its last mutation could act
DEFAULT_MINIMISE_TIMEOUT = 300.0  # s one bucket's minimisation may take (it holds a worker slot meanwhile)
MAX_CALIBRATION_CHECKS = 3  # batches of clean runs at a concurrency before the campaign takes what it has
MAX_WORKERS_PER_CORE = 4  # the local pool's threads: calibration picks at most this many runs a core
SETTLE_LOAD_SECONDS = 60.0  # after a change of runs at once, the 1-min load average needs this long to show it
# Before calibration (and for --cluster), the runs at once are estimated from the module count: a run's
# modules mostly sleep, and these leave headroom so deadline invariants do not starve (the measurements behind
# them: docs/performance.md, section "campaign").
CORES_PER_MODULE = 0.08
HELPER_CORES = 0.15  # the tool's own session, proxy and recorder per run


@dataclass(frozen=True, kw_only=True)
class CampaignConfig:
    spec_path: Path
    out: Path
    cases: int | None = None
    budget: float | None = None  # seconds
    workers: int | None = None
    seed: int = 0
    strategy: str = "random"
    dictionaries: list[Path] = field(default_factory=list)
    params: dict[str, list[str]] = field(default_factory=dict)  # key → values the cases spread over
    cluster: str | None = None
    horizon: float | None = None  # None: from the stack (clean runs to the scenario's end; see clean_horizon)
    baseline_runs: int = DEFAULT_BASELINE_RUNS  # clean runs per value of the params grid
    reruns: int = DEFAULT_RERUNS
    settle: float | None = DEFAULT_SETTLE  # None: a mutated case runs to the run's own end
    minimise: bool = True
    minimise_max_tests: int = 30
    minimise_timeout: float = DEFAULT_MINIMISE_TIMEOUT
    report: bool = True

    def resuming(self, meta: CampaignMeta) -> CampaignConfig:
        """This configuration continuing the campaign ``meta`` describes: its spec, seed, strategy, params and
        horizon as stored (a horizon derived from the stack is derived again, from the same clean runs), its case
        count unless this one gives one."""
        horizon = self.horizon if meta.horizon_derived else _stored(meta.horizon, self.horizon)
        return replace(self, spec_path=Path(meta.spec) if meta.spec is not None else self.spec_path,
                       seed=_stored(meta.seed, self.seed), strategy=_stored(meta.strategy, self.strategy),
                       params=_stored(meta.params, self.params), horizon=horizon,
                       cases=self.cases if self.cases is not None else meta.cases)


def _stored(stored: T | None, given: T) -> T:
    """The journal's value of a setting, the given one when the journal has none."""
    return stored if stored is not None else given


class StopReason(TextEnum):
    """Why a campaign ended (its text is what the command prints)."""

    DONE = "done"  # every case ran
    BUDGET = "budget"  # the time budget ran out
    INTERRUPTED = "interrupted"  # Ctrl-C: resume goes on from the journal


@dataclass
class CampaignResult:
    cases_done: int
    failures: int
    buckets: int
    seconds: float
    stopped: StopReason
    bugs: int = 0  # buckets confirmed as bugs (the rest: flaky/environment, baseline findings)


class CampaignStopped(AstaaDeftError):
    """The campaign cannot go on (the SUT does not start): one message, exit 2 (the command adds the fix)."""

    exit_code = 2


LIVE_STEP = 0.5  # s: the measured live time is rounded down to this (same cases for close measurements)


def live_timing(clean: list[CaseOutcome], horizon: float) -> Timing:
    """The anchor channel (its first message came last: every module is running) and the seconds the
    clean runs went on from there (the smallest), from the baseline's clean runs; the horizon without any."""
    anchors = [max(o.first_seen, key=lambda c: (o.first_seen[c], c)) for o in clean if o.first_seen]
    if not anchors:
        return Timing(None, horizon)
    anchor = max(set(anchors), key=lambda c: (anchors.count(c), c))
    lives = [o.seconds - o.first_seen[anchor] for o in clean if anchor in o.first_seen]
    live = max(LIVE_STEP, min(horizon, LIVE_STEP * int(min(lives) / LIVE_STEP)))
    return Timing(anchor, live)


def clean_horizon(spec: Spec, given: float | None) -> float:
    """Seconds a clean run may last: ``given`` (--horizon), else the spec's ``run: time_limit``, else (an end
    declared without a limit) CLEAN_RUN_CAP, else (no end declared: nothing to run to) DEFAULT_HORIZON. A clean
    run is never cut short of the scenario's end by default: it measures the SUT's own run."""
    if given is not None:
        return given
    run = spec.run
    if run is None or run.empty:
        return DEFAULT_HORIZON
    return run.time_limit if run.time_limit is not None else CLEAN_RUN_CAP


def derived_horizon(clean: list[CaseOutcome], cap: float) -> float:
    """Seconds a case may last, from the clean runs: the longest × HORIZON_SLACK, at most ``cap`` (the clean
    runs' own bound); ``cap`` without any finished clean run."""
    seconds = [o.seconds for o in clean if o.status == CaseStatus.DONE and o.seconds > 0]
    if not seconds:
        return cap
    return round(min(cap, max(seconds) * HORIZON_SLACK), 1)


def default_workers(module_count: int, cores: int | None = None) -> int:
    cores = cores or os.cpu_count() or 1
    per_run = HELPER_CORES + CORES_PER_MODULE * module_count
    return max(1, int(cores / per_run))


def param_grid(params: dict[str, list[str]], spec: Spec | None = None) -> list[dict[str, str]]:
    """Every combination of the values given per param and (with ``spec``) of the declared choices of the
    params given none; InputError for a given value outside its param's declared choices."""
    if spec is not None:
        check_param_values(spec, params, "--params")
        params = spread_choices(spec, params)
    keys = sorted(params)
    return [dict(zip(keys, values, strict=False)) for values in itertools.product(*(params[k] for k in keys))] or [{}]


class Campaign:
    def __init__(self, config: CampaignConfig, journal: Journal,
                 on_progress: Callable[[Campaign], None] = lambda c: None, say: Callable[[str], None] = print):
        self.config = config
        self.journal = journal
        self.on_progress = on_progress
        self.say = say
        self.spec = load_spec(config.spec_path)
        self.dictionary = load_dictionary(config.dictionaries)
        if config.strategy not in STRATEGIES:
            raise InputError(Problem("--strategy", None, None, f"unknown strategy '{config.strategy}'",
                                     f"use one of: {', '.join(STRATEGIES)}"))
        # Clean runs run to the scenario's end (capped by the run: section's time_limit); mutated cases get the
        # horizon derived from them after the baseline (the given --horizon bounds both).
        self.clean_horizon = clean_horizon(self.spec, config.horizon)
        self.horizon = self.clean_horizon
        self.strategy: Strategy = STRATEGIES[config.strategy](self.spec, self.dictionary, config.seed,
                                                              self.clean_horizon)
        self.grid = param_grid(config.params, self.spec)
        self.cores = os.cpu_count() or 1
        # Runs at once: the user's, else measured in the baseline (calibrate); this estimate until then.
        self.calibrated = config.workers is None and config.cluster is None
        self.workers = config.workers or default_workers(len(self.spec.modules))
        self.started = time.monotonic()
        self.timing = Timing(None, self.clean_horizon)
        self.known: dict[str, KnownFinding] = {}  # invariants the unmutated SUT breaks (judged after each run)
        self._clean: list[CaseOutcome] = []  # every finished clean run (baseline, twins, cases that mutated nothing)
        self._solo: dict[str, CaseOutcome] = {}  # params → a run alone: the timing reference
        self._last_change = time.monotonic()  # when the runs at once last changed (the load average lags)
        # Timing drifted at this many runs at once (None: never), with the other load then: not raised to it
        # again until the other load has fallen by CEILING_LOAD_DROP.
        self._ceiling: int | None = None
        self._ceiling_other = 0.0
        self._minimiser: ThreadPoolExecutor | None = None
        self._minimising: dict[Future, str] = {}  # minimisation in flight → its bucket
        self._running_cases: set[str] = set()
        self._cancel = threading.Event()  # set: minimisations in flight stop (the campaign was interrupted)
        self._fixed: set[str] = set()  # buckets `astaa-deft verify` found fixed: skipped unless they reappear
        self._testcases: dict[str, TestCase | None] = {}  # case id → its test case (the journal keeps the text)

    # -- the whole campaign --------------------------------------------------
    def run(self) -> CampaignResult:
        self.journal.set_meta(spec=str(self.config.spec_path.resolve()), seed=self.config.seed,
                              strategy=self.config.strategy, params=self.config.params, horizon=self.config.horizon,
                              horizon_derived=self.config.horizon is None, cases=self.config.cases,
                              budget=self.config.budget)
        requeued = self.journal.requeue_running()
        if requeued:
            self.say(f"resume: {requeued} case(s) that were in flight run again")
        if self.journal.requeue_minimisations():
            self.say("resume: the minimisations that were running start again")
        self._fixed = fixed_buckets(verification.verifications(self.journal))
        if self._fixed:
            self.say(f"resume: bucket(s) {', '.join(sorted(self._fixed))} verified fixed: skipped (not minimised)"
                     f" unless a case fails their way again")
        pool = self._pool()
        stopped = StopReason.DONE
        try:
            self._baseline(pool)
            stopped = self._main(pool)
        except KeyboardInterrupt:
            stopped = StopReason.INTERRUPTED
        finally:
            pool.close()
        try:
            if stopped != StopReason.INTERRUPTED and self.strategy.exports_own_findings:
                self.strategy.finish(self.journal, self.config.out, self.config.spec_path, self.say)
            elif stopped != StopReason.INTERRUPTED and self.config.minimise:
                self._minimise_left()
        except KeyboardInterrupt:
            stopped = StopReason.INTERRUPTED
        finally:
            if self._minimiser is not None:
                if stopped == StopReason.INTERRUPTED:  # minimisations in flight stop now; a resume does them again
                    self._cancel.set()
                self._minimiser.shutdown(wait=True, cancel_futures=True)
        done = [r for r in self.journal.cases() if r.finished]
        failures = sum(1 for r in done if r.kind == MUTATED and r.verdict not in (Verdict.PASS, None, "?"))
        live = self.journal.buckets(include_merged=False)
        return CampaignResult(len(done), failures, len(live), time.monotonic() - self.started, stopped,
                              bugs=sum(1 for b in live if b.is_bug))

    def _pool(self) -> CasePool:
        from astaa_deft.orchestration.campaign.executors import DaskPool, LocalPool

        if self.config.cluster:
            return DaskPool(self.config.cluster, self.workers)
        # Threads for as many runs as calibration may pick; the campaign keeps self.workers of them busy.
        return LocalPool(self.workers if not self.calibrated else self._most_workers())

    def _most_workers(self) -> int:
        return max(self.workers, MAX_WORKERS_PER_CORE * self.cores)

    # -- baseline: clean runs of every param value, the runs at once, the live time, known findings -------------
    def _baseline(self, pool: CasePool) -> None:
        per_value = max(1, self.config.baseline_runs)
        self._plan_baseline(per_value * len(self.grid))
        stored = self.journal.meta().workers
        if self.calibrated and stored is None:
            self._calibrate_workers(pool, per_value)
        else:
            if self.calibrated and stored is not None:  # resumed: as calibrated then
                self.workers = int(stored)
            self._run_pending_baseline(pool)
        rows = self.journal.cases(BASELINE)
        outcomes = [self.journal.outcome(r) for r in rows]
        failed = [o for o in outcomes if o is not None and o.status == CaseStatus.ERROR]
        if rows and len(failed) == len(rows):
            raise CampaignStopped(f"the SUT does not start: {failed[0].error or failed[0].summary}")
        # Runs of a batch whose timing drifted (too many at once) measured the campaign's load, not the SUT:
        # neither its live time nor its baseline findings.
        overloaded_runs = set(self.journal.meta().overloaded_runs)
        clean = [o for r, o in zip(rows, outcomes, strict=False)
                 if o is not None and o.status == CaseStatus.DONE and r.case_id not in overloaded_runs]
        self._derive_horizon(clean)
        self._calibrate(clean)
        self._file_baseline(rows, outcomes, overloaded_runs)
        self._solo = self._solo_runs()
        for row, outcome in zip(rows, outcomes, strict=False):
            if outcome is not None:
                self.strategy.observe_baseline(row.case_id, outcome)
        self._clean = clean + self._clean_failures_since_baseline()
        self.known = known_findings(self._clean)
        for name, finding in self.known.items():
            self.say(f"baseline finding: '{name}' breaks without mutation ({finding.rate} clean runs): from now on"
                     f" it counts in a case only where the case makes it worse (earlier, more often)")

    def _derive_horizon(self, clean: list[CaseOutcome]) -> None:
        """The cases' horizon from the clean runs (unless --horizon gave one): they ran to the scenario's end."""
        if self.config.horizon is not None:
            return
        self.horizon = derived_horizon(clean, self.clean_horizon)
        self.journal.set_meta(horizon=self.horizon)
        longest = max((o.seconds for o in clean), default=0.0)
        why = (f"the longest clean run took {longest:.1f} s to the scenario's end, × {HORIZON_SLACK:g}" if clean
               else "no clean run finished")
        self.journal.note("horizon", f"cases run at most {self.horizon:g} s: {why}; clean runs at most"
                                     f" {self.clean_horizon:g} s")
        self.say(f"baseline: cases run at most {self.horizon:g} s ({why})")

    def _file_baseline(self, rows: list[CaseRow], outcomes: list[CaseOutcome | None],
                       overloaded_runs: set[str]) -> None:
        """Failing baseline runs into baseline-finding buckets — except runs of a batch that overloaded the
        machine (their failures are the campaign's doing)."""
        for row, outcome in zip(rows, outcomes, strict=False):
            if outcome is None or not outcome.failed or row.bucket or row.case_id in overloaded_runs:
                continue
            signature = BucketSignature.clean(sig.failure_key(outcome))
            self.journal.file_case(row.case_id, signature,
                                   self._bucket(signature, outcome, row.case_id, BASELINE_FINDING))

    def _plan_baseline(self, count: int) -> None:
        """Baseline runs up to ``count``: run n has the grid's value (n-1) mod its size (every value in turn)."""
        for n in range(1, count + 1):
            params = {**self.grid[(n - 1) % len(self.grid)]}
            self._plan(PlannedCase(f"b-{n:04d}", BASELINE, n, self.config.seed, params, None, "baseline"))

    def _run_pending_baseline(self, pool: CasePool, at_once: int | None = None, last: int | None = None) -> None:
        """Run the planned baseline runs (numbered up to ``last``), ``at_once`` (default: the campaign's) at a time."""
        queue = [self._planned(c) for c in self.journal.pending(BASELINE) if last is None or c.number <= last]
        limit = at_once or self.workers
        while queue or pool.pending():
            while queue and pool.pending() < limit:
                self._submit(pool, queue.pop(0))
            for case_id, outcome in pool.done(timeout=0.5):
                self._finished(case_id, outcome)
            self.on_progress(self)

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

    def _clean_failures_since_baseline(self) -> list[CaseOutcome]:
        """On resume: failing twins and cases that mutated nothing, as known baseline findings again."""
        out = []
        for row in self.journal.cases():
            if row.kind not in (MUTATED, CONTROL) or row.status != CaseStatus.DONE:
                continue
            outcome = self.journal.outcome(row)
            if outcome is not None and outcome.failed and (row.kind == CONTROL or outcome.mutations == 0):
                out.append(outcome)
        return out

    def _calibrate(self, clean: list[CaseOutcome]) -> None:
        """Tell the strategy when the SUT is live: measured once in the baseline, kept in the journal."""
        stored = self.journal.meta().timing
        timing = stored if stored is not None else live_timing(clean, self.horizon)
        self.journal.set_meta(timing={"anchor": timing.anchor, "live": timing.live})
        self.timing = timing
        self.strategy.calibrate(timing)
        if timing.anchor is not None:
            self.say(f"baseline: the stack is live from the first '{timing.anchor}' message and runs"
                     f" {timing.live:g} s on; generated windows fall inside that")

    # -- generated cases -------------------------------------------------------
    def _main(self, pool: CasePool) -> StopReason:
        rows = self.journal.cases(MUTATED)
        if rows:  # guided: its schedule goes on where it was
            self.strategy.resume([self._planned(row) for row in rows])
        for row in rows:  # a resumed guided search learns its corpus again
            outcome = self.journal.outcome(row)
            if outcome is not None:
                self.strategy.observe(row.case_id, self._testcase(row), outcome)
        for bucket in self.journal.buckets():  # resumed between a bucket's last control run and its decision
            if bucket.kind == CONFIRMING and not self.journal.unfinished(bucket.bucket):
                self._decide(bucket.bucket)
        queue = [self._planned(row) for kind in (MUTATED, RERUN, CONTROL) for row in self.journal.pending(kind)]
        number = self.journal.max_number(MUTATED)
        stopped = StopReason.DONE
        while True:
            self._watch_load()
            self._collect_minimisations()
            self._start_minimisations(hunting=True)
            hunt_over = False  # the budget or the case count reached (not just every slot taken)
            while self._busy() < self.workers:
                if queue:
                    self._submit(pool, queue.pop(0))
                    continue
                if self._budget_over():
                    stopped, hunt_over = StopReason.BUDGET, True
                    break
                if self.config.cases is not None and number >= self.config.cases:
                    hunt_over = True
                    break
                number += 1
                case = self._plan_mutated(number)
                self._submit(pool, case)
            # Minimisations may hold every slot (one run at once on a heavy stack): the hunt waits for a slot.
            if not pool.pending() and not queue and (hunt_over or not self._minimising):
                return stopped
            for case_id, outcome in pool.done(timeout=0.5):
                queue.extend(self._finished(case_id, outcome))
            if not pool.pending():
                time.sleep(0.5)  # only minimisations hold the slots
            self.on_progress(self)

    def _busy(self) -> int:
        """Worker slots taken: cases in flight and minimisations running."""
        return len(self._running_cases) + len(self._minimising)

    def _plan_mutated(self, number: int) -> PlannedCase:
        proposal = self.strategy.propose(number)
        params = self.grid[(number - 1) % len(self.grid)]
        case = PlannedCase(f"c-{number:06d}", MUTATED, number, self.config.seed, params, proposal.testcase,
                           self.config.strategy, proposal.parent)
        self._plan(case)
        return case

    def _plan(self, case: PlannedCase) -> None:
        """Journal a planned case; its test case stays at hand as an object (the journal keeps its text)."""
        self._testcases[case.case_id] = case.testcase
        self.journal.plan(case)

    def _testcase(self, row: CaseRow) -> TestCase | None:
        """A planned case's test case: as planned, or (planned before a resume) read back from the journal,
        checked against the spec and dictionaries."""
        if row.case_id not in self._testcases:
            self._testcases[row.case_id] = read_testcase(row.testcase_xml, f"{self.journal.path}: {row.case_id}",
                                                         self.spec, self.dictionary)
        return self._testcases[row.case_id]

    def _planned(self, row: CaseRow) -> PlannedCase:
        return row.planned(self._testcase(row))

    def _budget_over(self) -> bool:
        return self.config.budget is not None and time.monotonic() - self.started >= self.config.budget

    def _submit(self, pool: CasePool, case: PlannedCase) -> None:
        horizon = self.clean_horizon if case.kind in (BASELINE, CONTROL) else self.horizon
        payload = CasePayload(str(self.config.spec_path.resolve()), case, str(self.case_dir(case.case_id)),
                              horizon, tuple(str(p.resolve()) for p in self.config.dictionaries),
                              settle=self.config.settle if case.kind in (MUTATED, RERUN) else None,
                              known=tuple(sorted(self.known)))
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
        more = raised(share, self.cores, available_memory_mb(), most=self._most_workers(), load1=load1, ours=ours,
                      workers=self.workers, ceiling=self._ceiling)
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

    # -- one finished case -----------------------------------------------------
    def _finished(self, case_id: str, outcome: CaseOutcome) -> list[PlannedCase]:
        self._running_cases.discard(case_id)
        row = self.journal.planned(case_id)
        kind, testcase = row.kind, self._testcase(row)
        outcome = sig.without_self_inflicted(outcome, testcase, self.spec)
        if kind in (MUTATED, RERUN):  # decictor: its oracle turns a run into a finding
            outcome = self.strategy.judge(case_id, testcase, outcome, kind == MUTATED)
        if kind != BASELINE:  # a known baseline finding counts only where this run makes it worse
            outcome = judged(outcome, self.known)
        new: list[PlannedCase] = []
        signature: BucketSignature | None = None
        key: FailureKey | None = None
        bucket: str | None = None
        if outcome.failed:
            key = sig.failure_key(outcome)
            clean = kind == BASELINE or (kind in (MUTATED, RERUN) and outcome.mutations == 0)
            if clean:  # no mutation acted: whatever failed, failed in a clean run — a baseline finding
                if kind != BASELINE:  # baseline runs are filed once calibrated (_file_baseline)
                    signature = BucketSignature.clean(key)
                    bucket = self._bucket(signature, outcome, case_id, BASELINE_FINDING)
                    self._learn_clean_failure(outcome)
            elif kind == MUTATED:
                signature = sig.signature(outcome, testcase)
                existing = self.journal.bucket_by_signature(signature)
                if existing is not None:
                    bucket = existing.bucket
                    self.journal.bucket_hit(bucket)
                    if bucket in self._fixed:  # verified fixed, and here it is again: it reopens
                        self._fixed.discard(bucket)
                        verification.reappeared(self.journal, bucket, case_id)
                        self.say(f"bucket {bucket} was verified fixed and reappeared in {case_id}: reopened")
                else:
                    bucket = self._bucket(signature, outcome, case_id, CONFIRMING)
                    new = self._plan_confirmation(bucket, row)
                    if not new:  # --reruns 0: nothing to confirm it with, filed as it is
                        self._decide(bucket)
            elif kind == RERUN:
                signature = sig.signature(outcome, testcase)
            elif kind == CONTROL:
                signature = BucketSignature.clean(key)
                self._learn_clean_failure(outcome)
        confirms = row.parent if kind in (RERUN, CONTROL) else None  # the bucket this run confirms
        if confirms is not None:
            first = self.journal.outcome(self.journal.planned(self.journal.bucket(confirms).first_case))
            same = outcome.failed and first is not None and shows_failure(outcome, first)
            if kind == RERUN and outcome.status == CaseStatus.DONE:
                self.journal.bucket_rerun(confirms, same and outcome.mutations > 0)
                if bucket is None and outcome.mutations > 0:  # filed under the bucket it re-runs
                    bucket = confirms
            elif kind == CONTROL and outcome.status == CaseStatus.DONE:
                self.journal.bucket_control(confirms, same)
                self._watch_timing(row, outcome)
        self.journal.finished(case_id, outcome, signature=signature, failure=key, bucket=bucket)
        self.journal.cost(case_id, outcome.cpu, os.getloadavg()[0], self.workers)
        if confirms is not None and not self.journal.unfinished(confirms):
            self._decide(confirms)
        if kind == MUTATED:
            self.strategy.observe(case_id, testcase, outcome)
        return new

    def _learn_clean_failure(self, outcome: CaseOutcome) -> None:
        """A clean run failed after the baseline: what it broke is a known baseline finding from now on."""
        self._clean.append(outcome)
        before = set(self.known)
        self.known = known_findings(self._clean)
        for name in sorted(set(self.known) - before):
            self.say(f"baseline finding: '{name}' broke in a run without mutation: from now on it counts in a case"
                     f" only where the case makes it worse")

    def _bucket(self, signature: BucketSignature, outcome: CaseOutcome, case_id: str, kind: BucketKind) -> str:
        existing = self.journal.bucket_by_signature(signature)
        if existing is not None:
            self.journal.bucket_hit(existing.bucket)
            return existing.bucket
        name = f"B{len(self.journal.buckets()) + 1:03d}"
        finding = sig.primary(outcome)
        family = signature.family
        invariant = finding.invariant if finding else "?"
        self.journal.add_bucket(NewBucket(name, signature, outcome.verdict, invariant,
                                          finding.module if finding else None, case_id,
                                          without_mutation=kind == BASELINE_FINDING,
                                          after_cases=self.journal.finished_count() + 1, kind=kind))
        if kind == BASELINE_FINDING:
            self.say(f"new bucket {name}: {outcome.verdict}: {invariant} (without mutation: a baseline finding)")
        else:
            self.say(f"failure in {case_id}: {outcome.verdict}: {invariant} — {family}: confirming it ({name}:"
                     f" {self.config.reruns} re-run(s), {self._controls()} unmutated twin(s))")
        return name

    def _controls(self) -> int:
        """Unmutated twins of a new failure: as many as its re-runs (so the two rates compare)."""
        return self.config.reruns

    def _plan_confirmation(self, bucket: str, row: CaseRow) -> list[PlannedCase]:
        """The failing case again (its rate) and its unmutated twins (same params, no test case): interleaved,
        so both see the same load."""
        cases = []
        params = row.params
        for k in range(1, max(self.config.reruns, self._controls()) + 1):
            if k <= self.config.reruns:
                cases.append(PlannedCase(f"r-{bucket}-{k}", RERUN, row.number, row.seed, params,
                                         self._testcase(row), row.strategy, parent=bucket))
            if k <= self._controls():
                cases.append(PlannedCase(f"t-{bucket}-{k}", CONTROL, row.number, row.seed, params, None,
                                         row.strategy, parent=bucket))
        for case in cases:
            self._plan(case)
        return cases

    def _decide(self, name: str) -> None:
        """A confirming bucket's re-runs and twins are in: a bug, or flaky / the environment's doing."""
        bucket = self.journal.bucket(name)
        if bucket.kind != CONFIRMING:
            return
        reproduced = bucket.rerun_failures > 0 or self.config.reruns == 0
        twin_failed = bucket.control_failures > 0
        kind = BUG if reproduced and not twin_failed else FLAKY
        self.journal.bucket_kind(name, kind)
        rates = (f"re-runs {bucket.rerun_failures}/{bucket.reruns} failed the same way, unmutated twin(s)"
                 f" {bucket.control_failures}/{bucket.controls}")
        if kind == BUG:
            self.say(f"new bucket {name}: {bucket.verdict}: {bucket.invariant} — {bucket.family} ({rates})")
            self._blame(bucket)
        else:
            why = "the unmutated twin fails that way too" if twin_failed else "it did not reproduce"
            self.say(f"flaky/environment {name}: {bucket.invariant} — {bucket.family}: {why} ({rates});"
                     f" not filed as a bug")

    # -- blame: the module whose output departed first from the twins'; one bucket per root cause -----------
    def _blame(self, bucket: Bucket) -> None:
        """Name the module to blame for a new bug (blame.py), journal the chain, and merge the bucket into an
        earlier one of the same root cause: the same module to blame, wrong output, failure and field family."""
        first = self.journal.planned(bucket.first_case)
        outcome = first.outcome()
        if outcome is None or not outcome.log_path:
            return
        twins = [Path(o.log_path) for r in self.journal.cases(CONTROL) if r.parent == bucket.bucket
                 for o in (r.outcome(),) if o is not None and o.status == CaseStatus.DONE and o.log_path]
        reruns = [Path(o.log_path) for r in self.journal.cases(RERUN) if r.parent == bucket.bucket
                  for o in (r.outcome(),) if o is not None and o.log_path and o.mutations > 0
                  and shows_failure(o, outcome)]
        finding = sig.primary(outcome)
        try:
            found = blame_logs(self.spec, [Path(outcome.log_path), *reruns], twins, self.timing.anchor,
                               invariant=bucket.invariant, finding_module=finding.module if finding else None)
        except BlameUnavailable as exc:
            self.journal.note("blame", f"{bucket.bucket}: no blame: {exc}")
            return
        identity = (None if found.module is None else
                    f"{found.module}|{found.wrong_output}|{sig.failure_signature(outcome)}|"
                    f"{sig.field_family(bucket.family)}")
        self.journal.blamed(BlameRow(bucket.bucket, found.module, found.output, found.how, found.chain, found.detail,
                                     found.twins, identity))
        self.say(f"  {bucket.bucket} blame: {found.module or '?'} ({found.chain}; {found.detail})")
        if identity is None:
            return
        blames = self.journal.blames()
        same = next((b for b in self.journal.buckets(include_merged=False)
                     if b.bucket != bucket.bucket and b.is_bug and blames.get(b.bucket) is not None
                     and blames[b.bucket].identity == identity), None)
        if same is not None:
            self.journal.merge_bucket(bucket.bucket, same.bucket)
            text = (f"bucket {bucket.bucket} ({bucket.family}) merged into {same.bucket} ({same.family}): one root"
                    f" cause — {found.module} to blame, {found.wrong_output}, {sig.field_family(bucket.family)}")
            self.journal.note("blame", text)
            self.say(f"  {text}")

    def _replay_confirms_blame(self, name: str, result: Minimised) -> None:
        """A minimisation that reproduced the failure in a replay of the module to blame alone, with the culprit
        frames, confirms the blame: journalled with it."""
        blamed = self.journal.blames().get(name)
        if blamed is None or blamed.module is None or result.exit_code != 0:
            return
        summary = minimised_summary(result.out_dir)
        if summary.get("tester") != "replay" or summary.get("replayed_module") != blamed.module:
            return
        frames = summary.get("frames")
        kept = frames.get("after") if isinstance(frames, dict) else None
        how = (f"a replay of {blamed.module} alone over {kept} frame(s) with the culprit fails as the run did"
               if kept is not None else f"a replay of {blamed.module} alone with the culprit fails as the run did")
        self.journal.blamed(replace(blamed, replay=how))
        self.say(f"  {name} blame confirmed: {how}")

    # -- minimisation: confirmed buckets, alongside the hunt, each in a worker slot ---------------------------
    def _start_minimisations(self, hunting: bool) -> None:
        if not self.config.minimise or self.strategy.exports_own_findings:
            return
        done = self.journal.minimisations()
        in_flight = set(self._minimising.values())
        # While hunting, at most half the slots (at least one) minimise: new cases go on in the rest.
        most = max(1, self.workers // 2) if hunting else self.workers
        for bucket in self.journal.buckets(include_merged=False):
            if len(self._minimising) >= most or self._busy() >= self.workers:
                return
            if not bucket.is_bug or bucket.bucket in done or bucket.bucket in in_flight or bucket.bucket in self._fixed:
                continue
            row = self.journal.planned(bucket.first_case)
            if not row.log_path or not Path(row.log_path).is_file():
                continue
            if self._minimiser is None:
                self._minimiser = ThreadPoolExecutor(max_workers=max(self.workers, 1) + 1,
                                                     thread_name_prefix="minimise")
            self.say(f"minimising bucket {bucket.bucket} ({bucket.invariant}) …")
            self.journal.minimisation_started(bucket.bucket)
            future = self._minimiser.submit(self._minimise_one, bucket, Path(row.log_path))
            self._minimising[future] = bucket.bucket

    def _minimise_one(self, bucket: Bucket, log: Path) -> tuple[Minimised, Path | None, TestsVerdict | None]:
        """One bucket's minimisation (a child process, time-boxed), its tests copied and run once on the defect:
        no journal, no output (it runs on a minimisation thread)."""
        out_dir = self.config.out / "minimised" / bucket.bucket
        if out_dir.exists():
            shutil.rmtree(out_dir)
        limits = MinimiseLimits(max_tests=self.config.minimise_max_tests, timeout=self.config.minimise_timeout)
        result = minimise_run(log, self.config.spec_path, out_dir, invariant=bucket.invariant, limits=limits,
                              cancel=self._cancel)
        tests_dir = None
        if result.tests_dir is not None:  # the minimiser's own: they fail on the culprit
            tests_dir = self.config.out / TESTS_DIR / bucket.bucket
            if tests_dir.exists():
                shutil.rmtree(tests_dir)
            shutil.copytree(result.tests_dir, tests_dir)
            verdict = run_module_tests(tests_dir, crash=is_crash_bucket(bucket.verdict, bucket.invariant, self.spec))
            return result, tests_dir, verdict
        return result, None, None

    def _collect_minimisations(self, wait: bool = False) -> None:
        if not self._minimising:
            return
        finished, _ = futures_wait(list(self._minimising), timeout=None if wait else 0,
                                   return_when=FIRST_COMPLETED)
        for future in finished:
            name = self._minimising.pop(future)
            result, tests_dir, verdict = future.result()
            status = "minimised" if result.exit_code == 0 else "not reproduced" if result.exit_code == 1 else "error"
            self.journal.minimised(Minimisation(name, status, result.exit_code, result.minimal_xml, result.culprit,
                                                str(result.out_dir), str(tests_dir) if tests_dir else None,
                                                result.seconds, result.detail))
            self.say(f"  {name} {status}: {result.culprit or '-'} ({result.seconds:.0f} s)")
            self._replay_confirms_blame(name, result)
            if tests_dir is not None and verdict is not None:
                self.say(f"  the minimiser's module tests{self._journal_module_tests(name, tests_dir, verdict)}")

    def _minimise_left(self) -> None:
        """After the hunt: the minimisations still running, then the confirmed buckets none took up, all the
        slots at once; the planner's module tests; buckets whose culprits coincide merged."""
        while True:
            self._collect_minimisations()
            self._start_minimisations(hunting=False)
            if not self._minimising:
                break
            self._collect_minimisations(wait=True)
        minimised = self.journal.minimisations()
        for bucket in self.journal.buckets(include_merged=False):
            row = minimised.get(bucket.bucket)
            if row is None or row.tests_dir or not self._planner_caused(bucket):
                continue
            log = self.journal.planned(bucket.first_case).log_path
            if log is None:  # minimised from its log, so it has one
                continue
            tests_dir = self._planner_tests(bucket, Path(log))
            if tests_dir is not None:
                self.journal.minimised(replace(row, tests_dir=str(tests_dir)))
        for merged, into in merge_same_culprits(self.journal):
            self.say(f"  bucket {merged}: same minimised culprit as {into}: merged")

    def _planner_caused(self, bucket: Bucket) -> bool:
        """The planner's bucket: its finding names the planner, or the planner is the module to blame (its
        module tests, replaying the failing run's frames, then check the blame)."""
        planner = self.spec.planner
        if planner is None:
            return False
        blamed = self.journal.blames().get(bucket.bucket)
        return bucket.module == planner.module or (blamed is not None and blamed.module == planner.module)

    def _planner_tests(self, bucket: Bucket, log: Path) -> Path | None:
        """DeFT module tests of the planner from the bucket's failing run (its frames with the culprit inputs).

        Built in a child process (``planner_tests``: this one runs threads, and
        the replay forks); a crash bucket's suite also gets the frame of the
        cycle the planner failed on. The suite is run once and the journal
        says whether it fails on the bucket's defect.
        """
        tests_dir = self.config.out / TESTS_DIR / f"{bucket.bucket}{REPLAY_TESTS_SUFFIX}"
        if tests_dir.exists():
            shutil.rmtree(tests_dir)
        built = build_planner_tests(log, self.config.spec_path, tests_dir, verdict=bucket.verdict,
                                    invariant=bucket.invariant)
        if not built.accepted:
            self.say(f"  no module tests: {built.error}")
            shutil.rmtree(tests_dir, ignore_errors=True)
            return None
        if built.failure_frame:
            self.say("  + the frame of the cycle the planner failed on")
        crash = is_crash_bucket(bucket.verdict, bucket.invariant, self.spec)
        self.say(f"  {built.accepted} DeFT module test(s) of the planner: pytest {tests_dir}"
                 f"{self._check_module_tests(bucket, tests_dir, crash)}")
        return tests_dir

    def _check_module_tests(self, bucket: Bucket, tests_dir: Path, crash: bool | None = None) -> str:
        """Run a bucket's module tests once and journal whether they fail on its defect; a phrase saying so."""
        if crash is None:
            crash = is_crash_bucket(bucket.verdict, bucket.invariant, self.spec)
        return self._journal_module_tests(bucket.bucket, tests_dir, run_module_tests(tests_dir, crash=crash))

    def _journal_module_tests(self, bucket: str, tests_dir: Path, verdict: TestsVerdict) -> str:
        """Journal whether a bucket's module tests fail on its defect; a phrase saying so."""
        self.journal.module_tests_checked(bucket, str(tests_dir), verdict.fails_on_defect, verdict.detail)
        how = {True: "they fail on the defect", False: "they do NOT fail on the defect", None: "they could not run"}
        return f"; {how[verdict.fails_on_defect]} ({verdict.detail})"


def shows_failure(outcome: CaseOutcome, failing: CaseOutcome) -> bool:
    """``outcome`` breaks what ``failing`` was filed under (its primary finding's invariant, in the same module),
    first or among its other findings: a twin that collides after first grazing an obstacle shows the collision
    too."""
    wanted = sig.primary(failing)
    if wanted is None:
        return outcome.failed and outcome.verdict == failing.verdict
    return outcome.failed and any(sig.same_failure(f, wanted) for f in outcome.findings)


TESTS_DIR = "tests"
REPLAY_TESTS_SUFFIX = "-replay"  # DeFT replays of the failing run (not the minimiser's failing oracle tests)


def merge_same_culprits(journal: Journal) -> list[tuple[str, str]]:
    """Merge each bucket whose minimised culprit is an earlier bucket's: (bucket, merged into) pairs.

    Two signatures can hide one bug (the same NaN breaks two invariants,
    first on one, then on the other; a second field that played no part):
    once minimised, the culprits say so. Culprits coincide when they change
    the same fields of the same channels, whatever the value (``heading =
    max`` and ``heading = big_1e16`` hang the same loop); message faults on
    the same channels (a reorder, a delay) that break the same invariant in
    the same module.
    Only confirmed minimisations count; the earliest bucket keeps the culprit.
    """
    minimised = journal.minimisations()
    owner: dict[str, str] = {}
    merged = []
    for bucket in journal.buckets():
        row = minimised.get(bucket.bucket)
        if not bucket.is_bug or row is None or row.exit_code != 0 or not row.culprit:
            continue
        family = culprit_family(row.culprit)
        if MESSAGE_FAULT in family:  # a reorder and a delay of one channel breaking the same thing: one bug
            family += f" → {bucket.invariant} in {bucket.module}"
        first = owner.setdefault(family, bucket.bucket)
        if first != bucket.bucket and bucket.merged_into != first:
            journal.merge_bucket(bucket.bucket, first)
            merged.append((bucket.bucket, first))
    return merged


MESSAGE_FAULT = "(message fault)"


def culprit_family(culprit: str) -> str:
    """A minimised culprit without its values, array indices folded; a fault on whole messages (reorder,
    delay, drop, …: no ``field = value``) as ``channel:(message fault)``."""
    parts = set()
    for part in (p.strip() for p in culprit.split(";")):
        if not part:
            continue
        if " = " in part:
            parts.add(sig.fold_indices(part.split(" = ", 1)[0]))
        else:
            parts.add(f"{part.rsplit(':', 1)[0]}:{MESSAGE_FAULT}")
    return "; ".join(sorted(parts))
