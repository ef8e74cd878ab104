"""The campaign's module-level search: generated faults replayed against every module the spec can replay, each
finding confirmed live.

After the baseline's clean runs, every module of the user's spec that runs alone
in process (the planner, a ``replay:`` entry with a ``factory``; never anything
a log names) is replayed from one clean baseline log on worker processes of its
own (:mod:`.module_level_worker`), one per idle core, under the faults of
:func:`~astaa_deft.analysis.deft.fault_plan.plan_faults` — the live generator's
dictionary values on its input fields, and message faults as the wire delivers
them — each judged like a live run (the invariants on its output, its crash, a
hang, frames it stops answering). A replay is deterministic, so a finding needs
no twin there; but a replay is open loop, so it is no bug of the stack yet:

* one bucket per (module, failure signature, field family); its first fault — one
  field of one message, or one message fault: minimal by construction — becomes a
  live test case (``m-0001`` …), run first in the hunt beside unmutated twins as
  every live case is, and its DeFT module test (the failing replay, a pytest file
  that fails while the module fails under that fault) is written and checked;
* a finding whose live case does not fail is *module-level only*, never a bug.

The baseline replays also say which input fields change any output of any
replayable module (:meth:`~astaa_deft.analysis.deft.module_search.ModuleBench.field_reads`):
live generation leaves out the fields no module reads (every consumer of the
channel probed, none reads it) and says how many and which.

Everything it decided is in ``DIR/module_level/state.json`` (a resumed campaign
reads it back and does not search again) and the journal's notes (topic
``module-level``).
"""

from __future__ import annotations

import json
import resource
import subprocess
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from astaa_deft.analysis.deft.module_search import ModuleVerdict
from astaa_deft.analysis.deft.planner_section import replay_modules
from astaa_deft.analysis.deft.stream_faults import FaultKind, FieldReads, StreamFault, fields_nothing_reads
from astaa_deft.engine.bus import process_launch
from astaa_deft.engine.bus.processes import python_module, stop_process
from astaa_deft.engine.intercept.actions.base import ActionConfig
from astaa_deft.engine.intercept.actions.delay import Delay
from astaa_deft.engine.intercept.actions.drop import Drop
from astaa_deft.engine.intercept.actions.duplicate import Duplicate
from astaa_deft.engine.intercept.actions.reorder import Reorder
from astaa_deft.engine.intercept.actions.set import Assignment, Set
from astaa_deft.engine.intercept.testcase import Policy, Selection, TestCase, Window
from astaa_deft.io.log.reader import read_log
from astaa_deft.io.statefile import StateReader, load_json
from astaa_deft.model.sut import Spec
from astaa_deft.orchestration.journal.journal import Journal
from astaa_deft.orchestration.campaign.level_split import LevelMeasure, Split, decide_split
from astaa_deft.orchestration.campaign.module_level_state import (
    DIR_NAME, ModuleFinding, ModuleLevelState, read_state, write_state,
)
from astaa_deft.orchestration.journal.model import BASELINE, MUTATED, CaseStatus, PlannedCase
from astaa_deft.orchestration.campaign.parts import CampaignParts
from astaa_deft.orchestration.journal.rows import CaseRow

STRATEGY = "module-level"  # the journal's strategy of a module-level finding's live case
CONFIRM_NUMBER_BASE = 1_000_000_000  # live cases of findings: numbered apart from the strategy's cases
PROBE_SHARE = 0.05  # of a --budget, the search's first round: what it measures decides the rest (level_split)
DEFAULT_SECONDS = 120.0  # its time box without a --budget
MIN_SECONDS = 10.0
MIN_ROUND_SECONDS = 5.0  # a second round shorter than this is not started
MAX_CONFIRMATIONS = 24  # live cases planned for findings (one per bucket, the first found first)
WORKER_GRACE = 30.0  # s past the deadline before a worker is stopped (a step in native code, the field probes)
LEAD_SECONDS = 0.02
WORKER_FIX = ("a module-level worker wrote what this version does not read: run the campaign again with one"
              " astaa-deft installed on every worker")
LIVE_SHARE = 0.8  # a live window opens this long before the message the fault hit arrived


def replayed_entries(spec: Spec) -> tuple[list, list[str]]:
    """The modules of the user's spec that run alone in process (the planner, ``replay:`` entries with a
    factory), one entry per module, the plant never; and why the others are not replayed."""
    entries, skipped, seen = [], [], set()
    for entry in replay_modules(spec):
        if entry.module in seen:
            continue
        if spec.is_plant(entry.module):  # it applies what it is sent: never the module to blame
            skipped.append(f"{entry.module}: the plant (plant: true): not searched at module level")
            continue
        if not entry.factory:
            skipped.append(f"{entry.module}: no in-process replay ('{entry.where}.factory'): fuzzed live only")
            continue
        seen.add(entry.module)
        entries.append(entry)
    return entries, skipped


def live_testcase(fault: StreamFault, case_id: str, *, seconds_after_anchor: float, anchor: str | None,
                  description: str) -> TestCase:
    """The live test case of a module-level fault: one policy on the fault's channel whose window opens just
    before the message the fault hit (counted from the anchor's first message, as the live cases are)."""
    action: ActionConfig
    limit = fault.count if fault.kind == FaultKind.HOLD else 1
    if fault.kind in (FaultKind.SET, FaultKind.HOLD):
        assert fault.path is not None and fault.value_ref is not None
        action = Set((Assignment(fault.path, fault.value_ref),))
    elif fault.kind == FaultKind.DROP:
        action = Drop()
    elif fault.kind == FaultKind.DELAY:
        action = Delay(fault.delay_ms)
    elif fault.kind == FaultKind.DUPLICATE:
        action = Duplicate()
    else:
        action = Reorder()
    start = max(0.0, round(seconds_after_anchor - LEAD_SECONDS, 3))
    window = Window(start, None, anchor, 1 if anchor is not None else None)
    policy = Policy(id="p1", action=action, channels=(fault.channel,), window=window, selection=Selection(limit=limit))
    return TestCase(id=case_id, seed=0, description=description, policies=(policy,))


class ModuleLevel(CampaignParts):
    """The module-level search, between the baseline and the hunt (module doc)."""

    def _module_level(self) -> None:
        out = self.config.out
        stored = read_state(out)
        if stored is not None and stored.complete:  # resumed: searched already; its live cases are in the journal
            self._leave_out(stored.unread, announce=False)
            return
        if stored is not None and stored.log is not None:  # interrupted after the search: finish what it decided
            self._finish(stored, Path(stored.log), dict(stored.params))
            return
        if not self.config.module_level:
            return
        if any(r.strategy != STRATEGY for r in self.journal.cases(MUTATED)):  # resumed: the hunt began without it
            return
        if self.strategy.exports_own_findings:  # its own search and export (decictor): every case of it live
            self.say(f"module level: --strategy {self.config.strategy} runs its own search live")
            return
        entries, skipped = replayed_entries(self.spec)
        if not entries:
            self.say("module level: no module of the spec can be replayed in process (the planner or a replay:"
                     " entry with a factory): every case runs live")
            return
        clean = self._clean_baseline_log()
        if clean is None:
            self.say("module level: no clean baseline run left a log to replay from: every case runs live")
            return
        log_path, params = clean
        from astaa_deft.analysis.deft.idle_cores import idle_cores

        seconds = self._module_level_seconds()
        if self._on_cluster():
            from astaa_deft.orchestration.campaign.module_level_cluster import cluster_cores

            cores = cluster_cores(str(self.config.cluster))
            where = f"{cores} worker(s) of the cluster at {self.config.cluster}"
        else:
            cores = idle_cores()  # the live pool waits meanwhile: what is idle now is the search's
            where = f"{cores} idle core(s) of {self.cores}"
        self.say(f"module level: replaying {', '.join(e.module for e in entries)} on their frames from"
                 f" {log_path.name} ({seconds:.0f} s, {where})")
        planned = [r.planned_at for r in self.journal.cases() if r.planned_at]
        began = time.time() - min(planned) if planned else 0.0
        state = _with(self._search(entries, skipped, log_path, seconds=seconds, cores=cores), started_after=began)
        unread = fields_nothing_reads({c.name: tuple(c.consumers) for c in self.spec.channels}, state.reads)
        self._finish(_with(state, unread=tuple(unread), params=dict(params)), log_path, params)

    def _finish(self, state: ModuleLevelState, log_path: Path, params: dict[str, str]) -> None:
        """Plan the findings' live cases, write their module tests, say what the search found. The state is
        written before each step and marked complete after the last, so an interrupt anywhere leaves the journal
        and the state agreeing, and a resume does only what is left (a live case already planned is kept)."""
        out = self.config.out
        write_state(out, state)
        state = self._confirm(state, log_path, params)
        write_state(out, state)
        state = _with(self._write_module_tests(state, log_path), complete=True)
        write_state(out, state)
        self._leave_out(state.unread, announce=True)
        for line in summary_lines(state, self.journal):
            self.journal.note("module-level", line)
            self.say(f"module level: {line}")

    def _module_level_seconds(self) -> float:
        """The first round's time box: the user's, else a probe of the budget (the split decides the rest after
        it), else the default."""
        if self.config.module_level_seconds is not None:
            return self.config.module_level_seconds
        if self.config.budget is not None:
            left = self.config.budget - (time.monotonic() - self.started)
            return max(MIN_SECONDS, min(PROBE_SHARE * self.config.budget, left / 2))
        return DEFAULT_SECONDS

    def _split(self, state: ModuleLevelState) -> Split | None:
        """The budget's split from the first round and the live runs so far (None: no --budget to split, or the
        user gave the search's seconds)."""
        if self.config.budget is None or self.config.module_level_seconds is not None:
            return None
        runs = [r for r in self.journal.cases() if r.finished and r.cpu and r.strategy != STRATEGY]
        live_cases = [r for r in runs if r.kind == MUTATED]
        live = live_figures(self.journal)
        module = LevelMeasure(cases=state.cases, cost=state.core_seconds / max(1, state.cases),
                              findings=len(state.findings))
        # a live case's cost: its runs' so far (the baseline's clean runs before the hunt began)
        cost = sum(r.cpu or 0.0 for r in runs) / len(runs) if runs else self.clean_horizon
        return decide_split(module=module, live=LevelMeasure(cases=len(live_cases), cost=cost,
                                                             findings=live.findings),
                            budget=self.config.budget)

    def _clean_baseline_log(self) -> tuple[Path, dict[str, str]] | None:
        """A clean baseline run's log (its run failed nothing) and its params; the first such."""
        for row in self.journal.cases(BASELINE):
            if row.status != CaseStatus.DONE or not row.log_path or not Path(row.log_path).is_file():
                continue
            outcome = self.journal.outcome(row)
            if outcome is not None and not outcome.failed:
                return Path(row.log_path), row.params
        return None

    def _window(self, log_path: Path) -> tuple[int, int, int | None]:
        """(live start, live end, the anchor's first message) in ns on the log's clock."""
        log = read_log(log_path)
        anchor = self.timing.anchor
        first = None
        if anchor is not None:
            times = [m.log_time for m in log.on(self.spec.channel(anchor).key)]
            first = min(times) if times else None
        bus = [m.log_time for m in log.messages if not m.topic.startswith("/astaa/")]
        start = first if first is not None else (min(bus) if bus else 0)
        # as live windows open (the first 80 % of the live part): a fault late in it may come after a live run's
        # scenario has ended, its case then mutating nothing
        end = start + int(LIVE_SHARE * self.timing.live * 1e9)
        return start, end, first

    def _search(self, entries: Sequence, skipped: list[str], log_path: Path, *, seconds: float,
                cores: int) -> ModuleLevelState:
        folder = self.config.out / DIR_NAME
        folder.mkdir(parents=True, exist_ok=True)
        start, end, _first = self._window(log_path)
        per_module = max(1, cores // len(entries))  # every module at least one worker
        jobs: list[tuple[str, dict[str, object]]] = []
        for number, entry in enumerate(entries):
            for part in range(per_module):
                name = _worker_name(number, part)  # the folder's own names: never a module name from the spec
                jobs.append((name, {"spec": str(self.config.spec_path.resolve()), "log": str(log_path.resolve()),
                                    "module": entry.module, "dictionaries": [str(p) for p in self.config.dictionaries],
                                    "seed": self.config.seed, "window": [start, end], "part": part,
                                    "parts": per_module, "settle": self.config.settle, "after": -1,
                                    "results": str(folder / f"{name}.jsonl"),
                                    "reads": str(folder / f"m{number}-reads.json") if part == 0 else None}))
                (folder / f"{name}.jsonl").unlink(missing_ok=True)
        started = time.monotonic()
        cpu = self._round(jobs, log_path=log_path, folder=folder, seconds=seconds)

        def collected() -> ModuleLevelState:
            return self._collect(entries, skipped, folder=folder, log_path=log_path, per_module=per_module,
                                 cpu=cpu or (time.monotonic() - started) * len(jobs), wall=time.monotonic() - started)

        state = collected()
        split = self._split(state)
        if split is None:
            return state
        more = min(split.seconds - (time.monotonic() - started),
                   self.config.budget - (time.monotonic() - self.started) - split.seconds)  # type: ignore[operator]
        exhausted = all(_exhausted(folder / f"{name}.jsonl") for name, _job in jobs)
        line = split.why + (": the plan is exhausted" if exhausted else
                            f": {more:.0f} s more" if more >= MIN_ROUND_SECONDS else ": no second round")
        self.journal.note("module-level", line)
        self.say(f"module level: {line}")
        if more >= MIN_ROUND_SECONDS and not exhausted:  # the plan goes on where each worker stopped
            cpu += self._round([(name, {**job, "reads": None, "after": _last_done(folder / f"{name}.jsonl")})
                                for name, job in jobs], log_path=log_path, folder=folder, seconds=more)
            state = collected()
        return _with(state, split=split)

    def _round(self, jobs: list[tuple[str, dict[str, object]]], *, log_path: Path, folder: Path,
               seconds: float) -> float:
        """One round of the workers (results appended to each job's file); their CPU seconds."""
        deadline = time.time() + seconds
        jobs = [(name, {**job, "deadline": deadline}) for name, job in jobs]
        if self._on_cluster():
            from astaa_deft.orchestration.campaign.module_level_cluster import run_on_cluster

            return run_on_cluster(str(self.config.cluster), jobs, log_path=log_path, folder=folder,
                                  deadline=deadline, grace=WORKER_GRACE)
        return _run_locally(jobs, folder=folder, deadline=deadline)

    def _on_cluster(self) -> bool:
        """Module-level workers go to the Dask cluster of ``--cluster tcp://…``; with ``local:K`` (this machine's
        processes anyway) they run as local processes of their own, K at once."""
        return bool(self.config.cluster) and not str(self.config.cluster).startswith("local:")

    def _collect(self, entries: Sequence, skipped: list[str], *, folder: Path, log_path: Path, per_module: int,
                 cpu: float, wall: float) -> ModuleLevelState:
        verdicts: list[tuple[int, ModuleVerdict]] = []
        modules, reads, counts = [], [], {}
        skipped = list(skipped)
        for number, entry in enumerate(entries):
            ok = False
            counts[entry.module] = 0
            for part in range(per_module):
                worker_file = folder / f"{_worker_name(number, part)}.jsonl"
                for line in _lines(worker_file):
                    if "error" in line:
                        skipped.append(f"{entry.module}: its replay could not start: {str(line['error'])[:300]}")
                    elif "setup" in line:
                        ok = True
                    elif "verdict" in line:
                        n, verdict = StateReader(str(worker_file), line, WORKER_FIX).fields(
                            "n", "verdict")
                        verdicts.append((n.whole() if n.present else 0, ModuleVerdict.from_json(verdict)))
                        counts[entry.module] += 1
            if ok:
                modules.append(entry.module)
            reads_file = folder / f"m{number}-reads.json"
            if reads_file.is_file():
                reads.append(FieldReads.from_json(StateReader(
                    str(reads_file), load_json(reads_file.read_bytes(), str(reads_file), "", WORKER_FIX), WORKER_FIX)))
        findings = bucket_findings([v for _n, v in verdicts])
        return ModuleLevelState(modules=tuple(modules), skipped=tuple(dict.fromkeys(skipped)), log=str(log_path),
                                cases=len(verdicts), core_seconds=cpu, wall_seconds=wall,
                                findings=tuple(findings), failing=sum(1 for _n, v in verdicts if v.failed),
                                reads=tuple(reads), per_module=counts)

    def _confirm(self, state: ModuleLevelState, log_path: Path, params: dict[str, str]) -> ModuleLevelState:
        """Plan one live case per bucket (the first found first, up to MAX_CONFIRMATIONS)."""
        if not state.findings:
            return state
        log = read_log(log_path)
        _start, _end, first = self._window(log_path)
        origin = first if first is not None else 0
        planned = {r.case_id for r in self.journal.cases(MUTATED)}
        confirmed = []
        for k, finding in enumerate(state.findings):
            if k >= MAX_CONFIRMATIONS:
                confirmed.append(finding)
                continue
            fault = finding.verdict.fault
            times = sorted(m.log_time for m in log.on(self.spec.channel(fault.channel).key))
            if fault.index >= len(times):
                confirmed.append(finding)
                continue
            case_id = f"m-{k + 1:04d}"
            description = (f"module-level {finding.name}: {fault.describe()} "
                           f"({finding.verdict.module}: {finding.verdict.signature})")
            if case_id in planned:  # planned before an interrupt: the same finding, the same case
                confirmed.append(_with_finding(finding, case_id=case_id))
                continue
            testcase = live_testcase(fault, f"tc-{case_id}", seconds_after_anchor=(times[fault.index] - origin) / 1e9,
                                     anchor=self.timing.anchor, description=description)
            self._plan(PlannedCase(case_id=case_id, kind=MUTATED, number=CONFIRM_NUMBER_BASE + k + 1,
                                   seed=self.config.seed, params=dict(params), testcase=testcase, strategy=STRATEGY,
                                   parent=finding.name))
            confirmed.append(_with_finding(finding, case_id=case_id))
        return _with(state, findings=tuple(confirmed))

    def _write_module_tests(self, state: ModuleLevelState, log_path: Path) -> ModuleLevelState:
        """Each finding's DeFT module test (the failing replay), checked by one pytest run over them all."""
        from astaa_deft.orchestration.campaign.module_level_tests import check_tests, write_test

        written = []
        for finding in state.findings:
            folder = self.config.out / DIR_NAME / "tests" / finding.name
            write_test(folder, spec_path=self.config.spec_path.resolve(), log_path=log_path.resolve(),
                       verdict=finding.verdict)
            written.append(_with_finding(finding, tests=str(folder.relative_to(self.config.out))))
        if not written:
            return state
        failing = check_tests(self.config.out / DIR_NAME / "tests")
        return _with(state, findings=tuple(
            _with_finding(f, tests_fail=failing.get(f.name)) for f in written))

    def _module_level_blame(self, bucket: str, case: CaseRow) -> tuple[str, str] | None:
        state = read_state(self.config.out)
        if state is None:
            return None
        # the bucket's first case, or a module-level case filed in it already (the live search found it too)
        filed = {case.case_id} | {r.case_id for r in self.journal.cases(MUTATED)
                                  if r.bucket == bucket and r.strategy == STRATEGY}
        finding = next((f for f in state.findings if f.case_id in filed), None)
        if finding is None:
            return None
        v = finding.verdict
        how = (f"module level {finding.name}: a replay of {v.module} alone on its frames from a clean run fails"
               f" under {v.fault.describe()} ({v.signature})")
        if finding.tests:
            fails = finding.tests_fail
            self.journal.module_tests_checked(
                bucket, str(self.config.out / finding.tests), fails,
                "the module-level replay fails under the fault" if fails else
                "its check did not fail" if fails is False else "its check did not run")
        return v.module, how

    def _leave_out(self, unread: Sequence[tuple[str, str]], *, announce: bool) -> None:
        if not unread:
            return
        left = self.strategy.leave_out(unread)
        if announce and left:
            shown = ", ".join(f"{c}:{p}" for c, p in unread[:12]) + (" …" if len(unread) > 12 else "")
            line = (f"{len(unread)} field(s) no replayed module reads left out of live generation"
                    f" ({left} generation target(s)): {shown}")
            self.journal.note("module-level", line)
            self.say(f"module level: {line}")


def _run_locally(jobs: Sequence[tuple[str, Mapping[str, object]]], *, folder: Path, deadline: float) -> float:
    """Each job in a worker process of its own on this machine, until the deadline (and its grace); their CPU
    seconds. Every worker is stopped on the way out, an interrupt included."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    workers = []
    try:
        for name, job in jobs:
            job_path = folder / f"{name}.job.json"
            job_path.write_text(json.dumps(job), encoding="utf-8")
            with open(folder / f"{name}.log", "wb") as log:
                workers.append(process_launch.start(
                    [*python_module("astaa_deft.orchestration.campaign.module_level_worker"), str(job_path)],
                    stdout=log, stderr=subprocess.STDOUT))
        for worker in workers:
            try:
                worker.wait(timeout=max(1.0, deadline + WORKER_GRACE - time.time()))
            except subprocess.TimeoutExpired:
                stop_process(worker, grace=2.0)
    finally:
        for worker in workers:
            if worker.poll() is None:
                stop_process(worker, grace=0.0)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def _last_done(path: Path) -> int:
    """The last fault of the plan a worker's results file shows done (-1: none)."""
    return max((int(line["n"]) for line in _lines(path) if "n" in line), default=-1)


def _exhausted(path: Path) -> bool:
    """Whether the worker went through its whole share of the plan (its last round ended before its deadline)."""
    ends = [line for line in _lines(path) if "done" in line]
    return bool(ends) and ends[-1]["exhausted"] is True


def _worker_name(module_number: int, part: int) -> str:
    return f"m{module_number}-{part}"


def _lines(path: Path) -> list[dict]:
    if not path.is_file():
        return []
    out = []
    for text in path.read_text(encoding="utf-8", errors="replace").splitlines():
        try:
            value = json.loads(text)
        except ValueError:
            continue  # the line a stopped worker was writing
        if isinstance(value, dict):
            out.append(value)
    return out


def bucket_findings(verdicts: Sequence[ModuleVerdict]) -> list[ModuleFinding]:
    """Failing verdicts into one bucket per (module, failure signature, field family), in the order found."""
    firsts: dict[tuple[str, str, str], ModuleVerdict] = {}
    counts: dict[tuple[str, str, str], int] = {}
    elapsed: dict[tuple[str, str, str], float] = {}
    spent: dict[str, float] = {}
    for verdict in verdicts:
        spent[verdict.module] = spent.get(verdict.module, 0.0) + verdict.seconds
        if not verdict.failed:
            continue
        key = verdict.bucket_key
        counts[key] = counts.get(key, 0) + 1
        if key not in firsts:
            firsts[key] = verdict
            elapsed[key] = spent[verdict.module]
    ordered = sorted(firsts, key=lambda key: elapsed[key])
    return [ModuleFinding(name=f"M{k + 1:03d}", verdict=firsts[key], count=counts[key], found_after=elapsed[key])
            for k, key in enumerate(ordered)]


def _with(state: ModuleLevelState, **changes: object) -> ModuleLevelState:
    from dataclasses import replace

    return replace(state, **changes)  # type: ignore[arg-type]


def _with_finding(finding: ModuleFinding, **changes: object) -> ModuleFinding:
    from dataclasses import replace

    return replace(finding, **changes)  # type: ignore[arg-type]


# -- what the status and the report say --------------------------------------------------------------------


@dataclass(frozen=True, kw_only=True)
class LevelFigures:
    """One level's figures: cases run, cases per core-hour, findings, confirmations, time to first find."""

    level: str
    cases: int
    core_seconds: float
    findings: int
    confirmed: int
    first_find: float | None  # s from the campaign's start

    @property
    def per_core_hour(self) -> float | None:
        return self.cases / (self.core_seconds / 3600.0) if self.core_seconds > 0 else None

    def line(self) -> str:
        rate = f"{self.per_core_hour:,.0f} cases per core-hour" if self.per_core_hour is not None else "rate unknown"
        first = (f"first find {self.first_find:.1f} s into the campaign" if self.first_find is not None
                 else "no find")
        return (f"{self.level}: {self.cases} case(s), {rate}, {self.findings} finding(s),"
                f" {self.confirmed} confirmed, {first}")


def finding_standing(finding: ModuleFinding, journal: Journal) -> str:
    """Where a module-level finding stands: confirmed live (its bucket a bug), module-level only, not yet."""
    if finding.case_id is None:
        return "not confirmed live (no live case planned: the confirmations' cap)"
    try:
        row = journal.planned(finding.case_id)
    except (KeyError, LookupError):
        return "not confirmed live yet"
    if not row.finished:
        return "not confirmed live yet (its live case has not run)"
    if row.bucket:
        bucket = next((b for b in journal.buckets() if b.bucket == row.bucket), None)
        if bucket is not None and bucket.is_bug:
            return f"confirmed live ({row.bucket})"
        if bucket is not None and bucket.kind == "confirming":
            return f"live case failed ({row.bucket}), being confirmed"
        return f"module-level only (its live case failed, {row.bucket}, but was not confirmed as a bug)"
    return "module-level only (its live case on the whole stack did not fail)"


def level_figures(state: ModuleLevelState, journal: Journal) -> tuple[LevelFigures, LevelFigures]:
    module = LevelFigures(level="module level", cases=state.cases, core_seconds=state.core_seconds,
                          findings=len(state.findings),
                          confirmed=sum(1 for f in state.findings
                                        if finding_standing(f, journal).startswith("confirmed")),
                          first_find=min((state.started_after + f.found_after for f in state.findings), default=None))
    return module, live_figures(journal)


def live_figures(journal: Journal) -> LevelFigures:
    rows = [r for r in journal.cases(MUTATED) if r.finished and r.strategy != STRATEGY]
    cpu = sum(r.cpu or 0.0 for r in rows)
    buckets = [b for b in journal.buckets(include_merged=False) if b.kind != "baseline"]
    own = {r.case_id for r in rows}
    live_buckets = [b for b in buckets if b.first_case in own]
    starts = [r.planned_at for r in journal.cases() if r.planned_at]
    origin = min(starts) if starts else None
    firsts = [r.finished_at for r in rows if r.finished_at and any(b.first_case == r.case_id for b in live_buckets)]
    first = min(firsts) - origin if firsts and origin is not None else None
    return LevelFigures(level="live", cases=len(rows), core_seconds=cpu, findings=len(live_buckets),
                        confirmed=sum(1 for b in live_buckets if b.is_bug), first_find=first)


def summary_lines(state: ModuleLevelState, journal: Journal) -> list[str]:
    lines = []
    if state.modules:
        lines.append(f"{state.cases} fault(s) replayed on {', '.join(state.modules)} in {state.wall_seconds:.0f} s"
                     f" ({state.core_seconds:.0f} CPU s), {state.failing} failing, {len(state.findings)} bucket(s)")
    lines += [f"not replayed: {why}" for why in state.skipped]
    for finding in state.findings:
        v = finding.verdict
        lines.append(f"{finding.name} {v.module}: {v.signature} — {v.fault.describe()} ({finding.count} fault(s));"
                     f" blame {v.module} (its replay fails); {finding_standing(finding, journal)}"
                     + (f"; module test {finding.tests}" + (" fails on the defect" if finding.tests_fail else
                        " does not fail on the defect" if finding.tests_fail is False else "")
                        if finding.tests else ""))
    return lines


def status_lines(out: Path, journal: Journal) -> list[str]:
    """``fuzz --status``'s module-level lines (none when the search did not run there)."""
    state = read_state(out)
    if state is None:
        return []
    module, live = level_figures(state, journal)
    lines = [module.line(), live.line()]
    if state.split is not None:
        lines.append(f"split: {state.split.why}")
    if module.per_core_hour and live.per_core_hour:
        lines.append(f"module level runs {module.per_core_hour / live.per_core_hour:,.0f}× the live cases per"
                     f" core-hour")
    if state.unread:
        lines.append(f"{len(state.unread)} field(s) no replayed module reads, left out of live generation: "
                     + ", ".join(f"{c}:{p}" for c, p in state.unread))
    lines += summary_lines(state, journal)[1:] if state.modules else summary_lines(state, journal)
    return lines


__all__ = ["CONFIRM_NUMBER_BASE", "STRATEGY", "LevelFigures", "ModuleFinding", "ModuleLevel", "ModuleLevelState",
           "bucket_findings", "level_figures", "live_testcase", "read_state", "replayed_entries", "status_lines",
           "summary_lines"]
