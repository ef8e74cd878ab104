"""The campaign workflow: baseline, generated cases, buckets, rates, minimisation, report.

Every decision reads from or writes to the journal first, so a campaign
stopped anywhere resumes where it was: finished cases stay finished, the
ones in flight run again, buckets and their re-runs pick up where they were.

:class:`Campaign` holds the hunt's loop; each concern is a part of its own
module (``parts.py`` says which and what they share): ``baseline.py``,
``scheduling.py``, ``judging.py``, ``minimisation_slots.py``.
"""

from __future__ import annotations

import itertools
import os
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TypeVar

from astaa_deft.model.records import Verdict
from astaa_deft.model.errors import InputError, Problem
from astaa_deft.engine.intercept.dictionary import load_dictionary
from astaa_deft.engine.intercept.testcase import TestCase
from astaa_deft.model.sut import Spec
from astaa_deft.engine.spec.params import check_grid, check_param_values, spread_choices
from astaa_deft.engine.spec.loader import load_spec
from astaa_deft.orchestration.journal.journal import Journal
from astaa_deft.orchestration.campaign.payload import CasePool
from astaa_deft.orchestration.journal.rows import CampaignMeta
from astaa_deft.orchestration.campaign.known import KnownFinding
from astaa_deft.orchestration.journal.model import (
    CONFIRMING, CONTROL, MUTATED, RERUN, CaseOutcome, PlannedCase, TextEnum, Timing,
)
from astaa_deft.orchestration.campaign.strategies import STRATEGIES, Strategy
from astaa_deft.orchestration.journal import verifications as verification
from astaa_deft.orchestration.journal.history import fixed_buckets
from astaa_deft.orchestration.campaign.baseline import (
    HORIZON_SLACK, CampaignStopped, Baseline, derived_horizon, live_timing,
)
from astaa_deft.orchestration.campaign.judging import Judging, shows_failure
from astaa_deft.orchestration.campaign.minimisation_slots import (
    REPLAY_TESTS_SUFFIX, TESTS_DIR, MinimisationSlots, culprit_family, merge_same_culprits,
)
from astaa_deft.orchestration.campaign.module_level import STRATEGY as MODULE_LEVEL, ModuleLevel
from astaa_deft.orchestration.campaign.scheduling import Scheduling

__all__ = [  # the campaign's own names, and those of its parts that its callers import from here
    "CLEAN_RUN_CAP", "DEFAULT_BASELINE_RUNS", "DEFAULT_HORIZON", "DEFAULT_MINIMISE_TIMEOUT", "DEFAULT_RERUNS",
    "DEFAULT_SETTLE", "HORIZON_SLACK", "REPLAY_TESTS_SUFFIX", "TESTS_DIR", "Campaign", "CampaignConfig",
    "CampaignResult", "CampaignStopped", "StopReason", "clean_horizon", "culprit_family", "default_workers",
    "derived_horizon", "live_timing", "merge_same_culprits", "param_grid", "shows_failure",
]

T = TypeVar("T")

DEFAULT_HORIZON = 20.0  # s a run may last when the spec's run: section declares no end at all
CLEAN_RUN_CAP = 600.0  # s a clean run may last when the run: section declares an end but no time_limit
DEFAULT_BASELINE_RUNS = 2
DEFAULT_RERUNS = 2
DEFAULT_SETTLE = 3.0  # s a mutated case runs on after its last mutation could act
DEFAULT_MINIMISE_TIMEOUT = 300.0  # s one bucket's minimisation may take (it holds a worker slot meanwhile)
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
    # Search at module level first where the spec can replay a module (module_level.py): `fuzz` turns it on
    # unless --no-module-level; a library caller asks for it.
    module_level: bool = False
    module_level_seconds: float | None = None  # its time box (None: a share of the budget)

    def resuming(self, meta: CampaignMeta, *, keep_spec: bool = False) -> CampaignConfig:
        """This configuration continuing the campaign ``meta`` describes: its spec (``keep_spec``: this one's,
        the user's), seed, strategy, params and horizon as stored (a horizon derived from the stack is derived
        again, from the same clean runs), its case count unless this one gives one."""
        horizon = self.horizon if meta.horizon_derived else _stored(meta.horizon, self.horizon)
        spec_path = self.spec_path if keep_spec or meta.spec is None else Path(meta.spec)
        return replace(self, spec_path=spec_path,
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


@dataclass(kw_only=True)
class CampaignResult:
    cases_done: int
    failures: int
    buckets: int
    seconds: float
    stopped: StopReason
    bugs: int = 0  # buckets confirmed as bugs (the rest: flaky/environment, baseline findings)


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


def _cluster_workers(address: str) -> int | None:
    from astaa_deft.orchestration.campaign.executors import cluster_workers  # imports dask: cluster campaigns only

    return cluster_workers(address)


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
    check_grid(params, "--params")
    keys = sorted(params)
    return [dict(zip(keys, values, strict=False)) for values in itertools.product(*(params[k] for k in keys))] or [{}]


class Campaign(Baseline, Scheduling, Judging, MinimisationSlots, ModuleLevel):
    """A fuzz campaign: baseline, generated cases, buckets, rates, minimisation — one part per concern
    (``parts.py``), the hunt's loop here."""

    def __init__(self, config: CampaignConfig, journal: Journal,
                 on_progress: Callable[[Campaign], None] = lambda c: None, say: Callable[[str], None] = print, *,
                 spec: Spec | None = None):
        """``spec``: the spec at ``config.spec_path`` as the caller loaded and checked it (None: loaded here)."""
        self.config = config
        self.journal = journal
        self.on_progress = on_progress
        self.say = say
        self.spec = spec if spec is not None else load_spec(config.spec_path)
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
        # On a cluster, by default as many runs at once as it has workers (each runs one case at a time).
        self.workers = (config.workers or (_cluster_workers(config.cluster) if config.cluster else None)
                        or default_workers(len(self.spec.modules)))
        self.started = time.monotonic()
        self.timing = Timing(None, self.clean_horizon)
        self.known: dict[str, KnownFinding] = {}  # invariants the unmutated SUT breaks (judged after each run)
        self.shutdown_delays: dict[str, float] = {}  # learned in the baseline (its clean runs use the default)
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
                              budget=self.config.budget, minimise=self.config.minimise)
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
            self._module_level()
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
        return CampaignResult(cases_done=len(done), failures=failures, buckets=len(live),
                              seconds=time.monotonic() - self.started, stopped=stopped,
                              bugs=sum(1 for b in live if b.is_bug))

    def _progress(self) -> None:
        self.on_progress(self)

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
        # A module-level finding's live case takes every other turn with the strategy's new cases: the findings
        # are confirmed early, and the live search goes on meanwhile (its cases find what no replay can).
        confirmations = [case for case in queue if case.strategy == MODULE_LEVEL]
        queue = [case for case in queue if case.strategy != MODULE_LEVEL]
        confirm_turn = True
        # the strategy's own cases (a module-level finding's live case is numbered apart)
        number = max((r.number for r in rows if r.strategy != MODULE_LEVEL), default=0)
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
                cases_done = self.config.cases is not None and number >= self.config.cases
                if confirmations and (confirm_turn or cases_done):
                    confirm_turn = False
                    self._submit(pool, confirmations.pop(0))
                    continue
                if cases_done:
                    hunt_over = True
                    break
                confirm_turn = True
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
            self._progress()

    def _plan_mutated(self, number: int) -> PlannedCase:
        proposal = self.strategy.propose(number)
        params = self.grid[(number - 1) % len(self.grid)]
        case = PlannedCase(case_id=f"c-{number:06d}", kind=MUTATED, number=number, seed=self.config.seed, params=params,
                           testcase=proposal.testcase, strategy=self.config.strategy, parent=proposal.parent)
        self._plan(case)
        return case

    def _budget_over(self) -> bool:
        return self.config.budget is not None and time.monotonic() - self.started >= self.config.budget


