"""The campaign workflow: baseline, generated cases, buckets, rates, minimisation, report.

Every decision reads from or writes to the journal first, so a campaign
stopped anywhere resumes where it was: finished cases stay finished, the
ones in flight run again, buckets and their re-runs pick up where they were.
"""

from __future__ import annotations

import itertools
import json
import os
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from collections.abc import Callable

from ..errors import AstaaDeftError, InputError, Problem
from ..intercept.dictionary import load_dictionary
from ..spec.model import Spec
from ..spec.params import check_param_values, spread_choices
from ..spec_loader import load_spec
from . import signature as sig
from .journal import Journal
from .minimiser import minimise_run
from .model import BASELINE, MUTATED, RERUN, CaseOutcome, PlannedCase
from .strategies import STRATEGIES, Strategy
from .strategies.base import Timing

DEFAULT_HORIZON = 20.0
DEFAULT_BASELINE_RUNS = 2
DEFAULT_RERUNS = 2
DEFAULT_SETTLE = 3.0  # s a mutated case runs on after its last mutation could act
# A run's modules mostly sleep: the demo's whole run (4 modules, proxy, recorder) used ~0.3 core on average
# (user+sys over wall time); these leave headroom so deadline invariants do not starve on a loaded machine
# (benchmarks/bench_campaign.py measures other counts).
# Measured with cases forked from a template (zygote.py) and recorders forked from the case: a demo case used
# 2.0-2.2 CPU s over its ~6.5 s — 0.33 core, 0.05 per module and 0.12 for the tool's process and recorder — and
# 6 at once ran 1.35x the cases of 3 (benchmarks/bench_campaign.py); 4 at once keeps a third of two cores spare.
CORES_PER_MODULE = 0.08
HELPER_CORES = 0.15  # the tool's own session, proxy and recorder per run


@dataclass
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
    horizon: float = DEFAULT_HORIZON
    baseline_runs: int = DEFAULT_BASELINE_RUNS
    reruns: int = DEFAULT_RERUNS
    settle: float | None = DEFAULT_SETTLE  # None: a mutated case runs to the run's own end
    minimise: bool = True
    minimise_max_tests: int = 30
    report: bool = True


@dataclass
class CampaignResult:
    cases_done: int
    failures: int
    buckets: int
    seconds: float
    stopped: str  # "done", "budget", "interrupted"


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
        self.strategy: Strategy = STRATEGIES[config.strategy](self.spec, self.dictionary, config.seed, config.horizon)
        self.grid = param_grid(config.params, self.spec)
        self.workers = config.workers or default_workers(len(self.spec.modules))
        self.started = time.monotonic()
        self.baseline_keys: dict[str, str] = {}  # failure key → its baseline bucket
        self.timing = Timing(None, config.horizon)

    # -- the whole campaign --------------------------------------------------
    def run(self) -> CampaignResult:
        self.journal.set_meta(spec=str(self.config.spec_path.resolve()), seed=self.config.seed,
                              strategy=self.config.strategy, params=self.config.params, horizon=self.config.horizon,
                              cases=self.config.cases, budget=self.config.budget)
        requeued = self.journal.requeue_running()
        if requeued:
            self.say(f"resume: {requeued} case(s) that were in flight run again")
        pool = self._pool()
        stopped = "done"
        try:
            self._baseline(pool)
            stopped = self._main(pool)
        except KeyboardInterrupt:
            stopped = "interrupted"
        finally:
            pool.close()
        finish = getattr(self.strategy, "finish", None)  # a strategy with its own findings (decictor)
        if stopped != "interrupted" and finish is not None:
            finish(self.journal, self.config.out, self.config.spec_path, self.say)
        elif stopped != "interrupted" and self.config.minimise:
            try:
                self._minimise_buckets()
            except KeyboardInterrupt:
                stopped = "interrupted"
        done = [r for r in self.journal.cases() if r["status"] in ("done", "error")]
        failures = sum(1 for r in done if r["kind"] == MUTATED and r["verdict"] not in ("Pass", None, "?"))
        return CampaignResult(len(done), failures, len(self.journal.buckets(include_merged=False)),
                              time.monotonic() - self.started, stopped)

    def _pool(self):
        from .executors import DaskPool, LocalPool

        if self.config.cluster:
            return DaskPool(self.config.cluster, self.workers)
        return LocalPool(self.workers)

    # -- baseline ------------------------------------------------------------
    def _baseline(self, pool) -> None:
        for n in range(1, self.config.baseline_runs + 1):
            params = {**self.grid[(n - 1) % len(self.grid)]}
            self.journal.plan(PlannedCase(f"b-{n:04d}", BASELINE, n, self.config.seed, params, None, "baseline"))
        for case in self.journal.pending(BASELINE):
            self._submit(pool, case)
        self._drain(pool, lambda: False)
        rows = self.journal.cases(BASELINE)
        outcomes = [self.journal.outcome(r) for r in rows]
        failed = [o for o in outcomes if o is not None and o.status == "error"]
        if rows and len(failed) == len(rows):
            raise CampaignStopped(f"the SUT does not start: {failed[0].error or failed[0].summary}")
        self._calibrate([o for o in outcomes if o is not None and o.status == "done"])
        seed_hook = getattr(self.strategy, "observe_baseline", None)  # decictor: the seed run
        for row, outcome in zip(rows, outcomes, strict=False):
            if seed_hook is not None and outcome is not None:
                seed_hook(row["case_id"], outcome)
            if outcome is not None and outcome.failed:
                self.baseline_keys.setdefault(sig.failure_key(outcome), row["bucket"])

    def _calibrate(self, clean: list[CaseOutcome]) -> None:
        """Tell the strategy when the SUT is live: measured once in the baseline, kept in the journal."""
        stored = self.journal.meta().get("timing")
        timing = Timing(**stored) if stored else live_timing(clean, self.config.horizon)
        self.journal.set_meta(timing={"anchor": timing.anchor, "live": timing.live})
        self.timing = timing
        calibrate = getattr(self.strategy, "calibrate", None)
        if calibrate is not None:
            calibrate(timing)
        if timing.anchor is not None:
            self.say(f"baseline: the stack is live from the first '{timing.anchor}' message and runs"
                     f" {timing.live:g} s on; generated windows fall inside that")

    # -- generated cases -------------------------------------------------------
    def _main(self, pool) -> str:
        rows = self.journal.cases(MUTATED)
        resume = getattr(self.strategy, "resume", None)  # guided: its schedule goes on where it was
        if resume is not None and rows:
            resume([(row["case_id"], row["testcase_xml"], row["parent"]) for row in rows])
        for row in rows:  # a resumed guided search learns its corpus again
            outcome = self.journal.outcome(row)
            if outcome is not None:
                self.strategy.observe(row["case_id"], row["testcase_xml"], outcome)
        queue = self.journal.pending(MUTATED) + self.journal.pending(RERUN)
        number = self.journal.max_number(MUTATED)
        stopped = "done"
        while True:
            while pool.pending() < self.workers * 2:
                if queue:
                    self._submit(pool, queue.pop(0))
                    continue
                if self._budget_over():
                    stopped = "budget"
                    break
                if self.config.cases is not None and number >= self.config.cases:
                    break
                number += 1
                case = self._plan_mutated(number)
                self._submit(pool, case)
            if not pool.pending():
                return stopped
            for case_id, outcome in pool.done(timeout=0.5):
                queue.extend(self._finished(case_id, outcome))
            self.on_progress(self)

    def _plan_mutated(self, number: int) -> PlannedCase:
        proposal = self.strategy.propose(number)
        params = self.grid[(number - 1) % len(self.grid)]
        case = PlannedCase(f"c-{number:06d}", MUTATED, number, self.config.seed, params, proposal.testcase_xml,
                           self.config.strategy, proposal.parent)
        self.journal.plan(case)
        return case

    def _budget_over(self) -> bool:
        return self.config.budget is not None and time.monotonic() - self.started >= self.config.budget

    def _submit(self, pool, case: PlannedCase) -> None:
        payload = {"spec": str(self.config.spec_path.resolve()), "case": case.to_json(),
                   "run_dir": str(self.case_dir(case.case_id)), "horizon": self.config.horizon,
                   "dictionaries": [str(p.resolve()) for p in self.config.dictionaries],
                   "settle": self.config.settle if case.kind != BASELINE else None}
        self.journal.started(case.case_id)
        pool.submit(case.case_id, payload)

    def case_dir(self, case_id: str) -> Path:
        return (self.config.out / "cases" / case_id).resolve()

    def _drain(self, pool, stop: Callable[[], bool]) -> None:
        while pool.pending():
            for case_id, outcome in pool.done(timeout=0.5):
                self._finished(case_id, outcome)
            self.on_progress(self)

    # -- one finished case -----------------------------------------------------
    def _finished(self, case_id: str, outcome: CaseOutcome) -> list[PlannedCase]:
        row = self.journal.planned(case_id)
        kind, xml = row["kind"], row["testcase_xml"]
        outcome = sig.without_self_inflicted(outcome, xml, self.spec)
        judge = getattr(self.strategy, "judge", None)  # decictor: its oracle turns a run into a finding
        if judge is not None and kind in (MUTATED, RERUN):
            outcome = judge(case_id, xml, outcome, kind == MUTATED)
        new: list[PlannedCase] = []
        signature: str | None = None
        key: str | None = None
        bucket: str | None = None
        if outcome.failed:
            key = sig.failure_key(outcome)
            if kind == BASELINE:
                signature = f"{key}|{sig.NO_MUTATION}"
                bucket = self._bucket(signature, outcome, case_id, True)
            elif kind == RERUN:
                signature = sig.signature(outcome, xml)
            elif key in self.baseline_keys:  # the SUT fails this way without mutation too: not the mutation's
                signature = f"{key}|{sig.NO_MUTATION}"
                bucket = self.baseline_keys[key]
                self.journal.bucket_hit(bucket)
            else:
                signature = sig.signature(outcome, xml)
                existing = self.journal.bucket_by_signature(signature)
                if existing is not None:
                    bucket = existing.bucket
                    self.journal.bucket_hit(bucket)
                else:
                    bucket = self._bucket(signature, outcome, case_id, False)
                    new = self._plan_reruns(bucket, row)
        if kind == RERUN:
            bucket = row["parent"]
            first = self.journal.outcome(self.journal.planned(self._first_case(bucket)))
            same = outcome.failed and first is not None and sig.failure_key(first) == key
            if outcome.status == "done":
                self.journal.bucket_rerun(bucket, same)
        self.journal.finished(case_id, outcome, signature, key, bucket)
        if kind == MUTATED:
            self.strategy.observe(case_id, xml, outcome)
        return new

    def _first_case(self, bucket: str) -> str:
        return next(b.first_case for b in self.journal.buckets() if b.bucket == bucket)

    def _bucket(self, signature: str, outcome: CaseOutcome, case_id: str, baseline: bool) -> str:
        existing = self.journal.bucket_by_signature(signature)
        if existing is not None:
            self.journal.bucket_hit(existing.bucket)
            return existing.bucket
        name = f"B{len(self.journal.buckets()) + 1:03d}"
        finding = sig.primary(outcome)
        done = sum(1 for r in self.journal.cases() if r["status"] in ("done", "error"))
        self.journal.add_bucket(name, signature, outcome.verdict, finding.invariant if finding else "?",
                                finding.module if finding else None, signature.split("|")[-1], case_id, baseline,
                                done + 1)
        self.say(f"new bucket {name}: {outcome.verdict}: {finding.invariant if finding else '?'}"
                 f"{' (without mutation)' if baseline else ''} — {signature.split('|')[-1]}")
        return name

    def _plan_reruns(self, bucket: str, row) -> list[PlannedCase]:
        cases = []
        for k in range(1, self.config.reruns + 1):
            case = PlannedCase(f"r-{bucket}-{k}", RERUN, row["number"], row["seed"], json.loads(row["params"]),
                               row["testcase_xml"], row["strategy"], parent=bucket)
            self.journal.plan(case)
            cases.append(case)
        return cases

    # -- minimisation ------------------------------------------------------------
    def _minimise_buckets(self) -> None:
        done = self.journal.minimisations()
        for bucket in self.journal.buckets(include_merged=False):
            if bucket.without_mutation or bucket.bucket in done:
                continue
            row = self.journal.planned(bucket.first_case)
            if not row["log_path"] or not Path(row["log_path"]).is_file():
                continue
            self.say(f"minimising bucket {bucket.bucket} ({bucket.invariant}) …")
            out_dir = self.config.out / "minimised" / bucket.bucket
            if out_dir.exists():
                shutil.rmtree(out_dir)
            result = minimise_run(Path(row["log_path"]), self.config.spec_path, out_dir, bucket.invariant,
                                  max_tests=self.config.minimise_max_tests)
            tests_dir = None
            if result.tests_dir is not None:  # the minimiser's own: they fail on the culprit
                tests_dir = self.config.out / TESTS_DIR / bucket.bucket
                if tests_dir.exists():
                    shutil.rmtree(tests_dir)
                shutil.copytree(result.tests_dir, tests_dir)
            elif self._planner_caused(bucket):
                tests_dir = self._planner_tests(bucket, Path(row["log_path"]))
            status = "minimised" if result.exit_code == 0 else "not reproduced" if result.exit_code == 1 else "error"
            self.journal.minimised(bucket.bucket, status, result.exit_code, result.minimal_xml, result.culprit,
                                   str(out_dir), str(tests_dir) if tests_dir else None, result.seconds,
                                   result.detail)
            self.say(f"  {status}: {result.culprit or '-'} ({result.seconds:.0f} s)")
        for merged, into in merge_same_culprits(self.journal):
            self.say(f"  bucket {merged}: same minimised culprit as {into}: merged")

    def _planner_caused(self, bucket) -> bool:
        planner = self.spec.planner
        return planner is not None and bucket.module == planner.module

    def _planner_tests(self, bucket, log: Path) -> Path | None:
        """DeFT module tests of the planner from the bucket's failing run (its frames with the culprit inputs)."""
        from ..deft.workflow import extract_module_tests

        tests_dir = self.config.out / TESTS_DIR / f"{bucket.bucket}{REPLAY_TESTS_SUFFIX}"
        if tests_dir.exists():
            shutil.rmtree(tests_dir)
        try:
            report = extract_module_tests(log, self.config.spec_path, tests_dir, jobs=1)
        except InputError as exc:
            self.say(f"  no module tests: {exc}")
            return None
        if not report.accepted:
            self.say("  no module tests: no planner output of the run replayed exactly")
            shutil.rmtree(tests_dir, ignore_errors=True)
            return None
        oracle = add_invariant_oracle(tests_dir, self.spec, bucket.invariant)
        verdict = ""
        if oracle:  # the suite must fail while the planner breaks the invariant: check it once
            suite = tests_dir.resolve()  # -o may be relative: pytest runs from inside the suite
            done = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", str(suite)],
                                  capture_output=True, text=True, timeout=600, cwd=suite)
            verdict = (f"; it fails as it should (oracle: {bucket.invariant})" if done.returncode == 1
                       else f"; its oracle ({bucket.invariant}) did not fail (pytest exit {done.returncode})")
        self.say(f"  {report.accepted} DeFT module test(s) of the planner: pytest {tests_dir}{verdict}")
        return tests_dir


TESTS_DIR = "tests"
REPLAY_TESTS_SUFFIX = "-replay"  # DeFT replays of the failing run (not the minimiser's failing oracle tests)


def add_invariant_oracle(tests_dir: Path, spec, invariant: str) -> bool:
    """Give an extracted suite an oracle that fails while the replayed plans break ``invariant``.

    Only for an invariant on the planner's output channel (what a replay
    produces); the frames alone only check that the replay matches the
    recording, which a defect reproduced exactly passes. True if added.
    """
    from ..deft.export import MANIFEST
    from ..deft.invariant_oracle import oracle_entry

    planner = spec.planner
    watched = next((inv for inv in spec.invariants if inv.name == invariant), None)
    if planner is None or watched is None or getattr(watched, "channel", None) != planner.output:
        return False
    manifest_path = tests_dir / MANIFEST
    manifest = json.loads(manifest_path.read_text())
    frames = manifest.get("frames") or []
    if not frames:
        return False
    manifest.setdefault("oracles", []).append(
        oracle_entry(invariant, frames[-1]["index"], int(frames[0]["output_time_ns"])))
    manifest_path.write_text(json.dumps(manifest, indent=1) + "\n")
    return True


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
        if bucket.without_mutation or row is None or row["exit_code"] != 0 or not row["culprit"]:
            continue
        family = culprit_family(row["culprit"])
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
