"""The three minimisation stages over ddmin, for either tester.

1. **Mutations** — ddmin over the run's mutations: which of them does the
   failure need? A held fault (one policy on consecutive messages of a
   channel) is one item (:mod:`.holds`); each surviving hold is then
   shortened at its ends (**hold**), never thinned from inside.
2. **Scaffolding** (replay only) — ddmin over the frames before the first
   failing output: the shortest history the planner needs to fail again
   (planners carry state, so the failing frame alone may not be enough). The
   failing frame itself is always kept; each test replays a fresh planner
   over the kept frames.
3. **Fields** — within each surviving mutation that set several fields,
   which field changes matter (replay: the other fields reverted in the
   message; live: a pinned policy setting fewer fields).

This module only orchestrates: it turns subsets into tester calls and ddmin
results into a :class:`Minimisation`. The algorithm is :mod:`.ddmin`'s, the
verdicts are the testers'. Which failure to minimise and which tester can
judge it are decided here too (:func:`find_failures`, :func:`choose_tester`).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from astaa_deft.model.vocabulary import TextEnum

from astaa_deft.model.errors import InputError, Problem
from astaa_deft.io.log.reader import LogContents
from astaa_deft.engine.monitor import check_log, with_typed_invariants
from astaa_deft.engine.monitor.base import ReplayJudges
from astaa_deft.engine.monitor.kinds import invariant_class
from astaa_deft.engine.monitor.verdict import IMPLICIT
from astaa_deft.model.records import Violation
from astaa_deft.model.sut import Spec
from astaa_deft.engine.spec.replay_section import ReplayModule
from astaa_deft.analysis.minimise.failure import Failure
from astaa_deft.analysis.minimise.ddmin import DDOptions, DDResult, Outcome, OutcomeCache, TestResult, ddmin, shorten
from astaa_deft.analysis.minimise.holds import Run, flatten, held_runs, same_fields
from astaa_deft.analysis.minimise.live_tester import LiveTester
from astaa_deft.analysis.minimise.mutations import FieldSelection, Mutation, run_start_ns
from astaa_deft.analysis.minimise.replay_model import Job, ReplayModel, replay_entry_for
from astaa_deft.analysis.minimise.replay_tester import DeftTester


def find_failure(log: LogContents, spec: Spec, invariant: str | None) -> Failure:
    """The first violation of ``invariant`` (or the first of all) in the log (InputError if none)."""
    return find_failures(log, spec, invariant)[0]


def find_failures(log: LogContents, spec: Spec, invariant: str | None, *, most: int = 1) -> list[Failure]:
    """The failures to minimise, in time order (InputError if none): ``invariant``'s first violation; without
    one, the first violation of each distinct invariant broken in the run (a crash no invariant named
    counts as one), at most ``most`` of them.

    The log is judged again by the spec's monitors, as ``astaa-deft check``
    does, rather than trusting the violation events the online monitors
    logged: the testers judge their runs that way too, so the failure they
    look for is the one found the same way.
    """
    start_ns = run_start_ns(log)
    result = check_log(log, with_typed_invariants(spec))
    found = list(result.violations)
    first = result.verdict.first
    if first is not None and first.invariant == IMPLICIT:  # a crash no invariant named: in the verdict only
        found.append(first)
    found.sort(key=lambda v: v.time_ns)
    if invariant is not None:
        chosen = [v for v in found if v.invariant == invariant]
        if not chosen:
            broken = sorted({v.invariant for v in found})
            raise InputError(Problem(str(log.path), None, None, f"invariant '{invariant}' never broke in this run",
                                     f"broken in it: {', '.join(broken)}" if broken else "nothing broke in it"))
        found, most = chosen, 1
    if not found:
        raise InputError(Problem(str(log.path), None, None, "the run did not fail: no invariant broke, "
                                 "no module crashed", "minimise a log whose run failed (astaa-deft check LOG)"))
    firsts: dict[str, Violation] = {}  # each invariant's first violation, in time order
    for v in found:
        firsts.setdefault(v.invariant, v)
    return [Failure(invariant=v.invariant, kind=v.invariant_kind, module=v.module, channel=v.channel,
                    at=((v.time_ns or start_ns) - start_ns) / 1e9, detail=v.detail, crash=v.crash)
            for v in list(firsts.values())[:most]]


class TesterKind(TextEnum):
    """What judges a subset of mutations: a replay of one module, or whole-system re-runs."""

    REPLAY = "replay"
    LIVE = "live"


@dataclass(frozen=True)
class TesterChoice:
    """The tester chosen for a failure, why (shown to the user), and for REPLAY the module replayed."""

    tester: TesterKind
    why: str
    entry: ReplayModule | None = None  # set exactly when ``tester`` is REPLAY


def choose_tester(spec: Spec, failure: Failure, live_only: bool) -> TesterChoice:
    """Replay the module whose output alone decides ``failure`` when the spec can replay it, else live."""
    if live_only:
        return TesterChoice(TesterKind.LIVE, "--live-only")
    entry, why_not = replay_entry_for(spec, failure.invariant, failure.module)
    if entry is None:
        return TesterChoice(TesterKind.LIVE, f"{why_not}: whole-system re-runs")
    if entry.where == "planner":
        return TesterChoice(TesterKind.REPLAY, f"'{failure.invariant}' reads only the planner's output: planner replay",
                            entry)
    if failure.invariant == IMPLICIT or invariant_class(failure.kind).replay_judges is ReplayJudges.PROCESS:
        return TesterChoice(TesterKind.REPLAY, (f"module '{entry.module}' crashed, and its replay shows crashes: "
                                            f"module replay ({entry.where})"), entry)
    return TesterChoice(TesterKind.REPLAY, (f"'{failure.invariant}' reads only module '{entry.module}''s output "
                                        f"'{entry.output}': module replay ({entry.where})"), entry)


@dataclass(kw_only=True)
class StageReport:
    name: str
    unit: str  # what was minimised: "mutations", "frames", "fields"
    before: int
    after: int
    tests_run: int = 0
    cache_hits: int = 0
    seconds: float = 0.0
    complete: bool = True
    note: str = ""

    @classmethod
    def of(cls, name: str, unit: str, before: int, result: DDResult, *, extra_tests: int = 0,
           note: str = "") -> StageReport:
        return cls(name=name, unit=unit, before=before, after=len(result.minimal),
                   tests_run=result.tests_run + extra_tests, cache_hits=result.cache_hits, seconds=result.seconds,
                   complete=result.complete, note=note)


@dataclass(kw_only=True)
class Minimisation:
    """What survived, and what it cost."""

    tester: TesterKind
    failure: Failure
    mutations: list[Mutation]  # every effective mutation of the log
    kept: dict[int, FieldSelection]  # the minimal mutations (number → fields kept; None: all)
    stages: list[StageReport] = field(default_factory=list)
    outputs_replayed: int = 0  # replay: frames before the failure in the run …
    frames: list[int] = field(default_factory=list)  # … and those kept (output indices), failing one last
    failing_output: int | None = None
    detail: str = ""  # the failure as the final test saw it
    failure_rate: float | None = None  # live: the rate the last stage saw for the minimal set
    notes: list[str] = field(default_factory=list)

    @property
    def chosen(self) -> list[tuple[Mutation, FieldSelection]]:
        by_number = {m.number: m for m in self.mutations}
        return [(by_number[n], selection) for n, selection in sorted(self.kept.items())]

    def fields_count(self) -> int:
        """Field changes in the minimal mutations."""
        return sum(len(m.fields) if s is None else len(s) for m, s in self.chosen)


Say = Callable[[str], None]


def _stage_progress(say: Say, name: str) -> Callable[[str], None]:
    return lambda line: say(f"  [{name}] {line}")


def minimise_replay(tester: DeftTester, model: ReplayModel, failure: Failure, parallel: int,
                    *, say: Say = lambda line: None, max_tests: int | None = None) -> Minimisation:
    """The three stages with the planner replay (raises NotReproducible / FailsWithoutItems from stage 1)."""
    relevant = model.streams.relevant
    out = Minimisation(tester=TesterKind.REPLAY, failure=failure, mutations=model.mlog.mutations, kept={})
    ignored = len(model.mlog.mutations) - len(relevant)
    who = "the planner" if model.cfg.where == "planner" else "the module"
    if ignored:
        out.notes.append(f"{ignored} mutation(s) did not reach {who} ({model.cfg.module}) and cannot "
                         f"change its replay: not tested")

    # Stage 1: mutations (a held fault one item), then the holds shortened.
    runs = held_runs(relevant)
    say(f"stage 1: {len(relevant)} mutations reaching {who}" + _runs_note(runs))
    first = ddmin(runs, lambda subset: tester(Job.of({n: None for n in flatten(subset)})),
                  DDOptions(parallel=parallel, max_tests=max_tests, progress=_stage_progress(say, "mutations")))
    report = StageReport.of("mutations", "mutations", len(model.mlog.mutations), first,
                            note=f"{len(relevant)} reached {who}{_runs_note(runs)}")
    report.after = len(flatten(first.minimal))
    out.stages.append(report)
    kept_runs, _ = _shorten_holds(first.minimal, lambda subset: tester(Job.of({n: None for n in flatten(subset)})),
                                  max_tests, say, out=out)
    kept: dict[int, FieldSelection] = {n: None for n in flatten(kept_runs)}
    answer = tester.answer(Job.of(kept))
    failing = answer.failing_output
    if answer.result.outcome is not Outcome.FAIL or failing is None:
        # A violation only the end of the run decides (a temporal invariant's future): no failing
        # frame to build a history for; every frame stays.
        out.kept, out.detail = kept, answer.result.detail
        out.frames = [i for i, frame in enumerate(model.frames(kept)) if frame is not None]
        out.outputs_replayed = len(out.frames)
        return out

    # Stage 2: scaffolding frames.
    frames = model.frames(kept)
    preceding = [i for i in range(failing) if frames[i] is not None]
    out.outputs_replayed = len(preceding) + 1
    say(f"stage 2: {len(preceding)} frames before the failing output {failing}")
    started = time.monotonic()
    alone = tester(Job.of(kept, [failing]))
    if alone.outcome is Outcome.FAIL:
        scaffolding: list[int] = []
        out.stages.append(StageReport(name="scaffolding", unit="frames", before=len(preceding) + 1, after=1,
                                      tests_run=1, cache_hits=0, seconds=time.monotonic() - started,
                                      note="the failing frame alone fails"))
    else:
        options = DDOptions(parallel=parallel, check_full=False, max_tests=max_tests,
                            progress=_stage_progress(say, "frames"))
        second = ddmin(preceding, lambda subset: tester(Job.of(kept, [*subset, failing])), options)
        scaffolding = list(second.minimal)
        report = StageReport.of("scaffolding", "frames", len(preceding) + 1, second, extra_tests=1)
        report.after += 1  # the failing frame
        out.stages.append(report)
    out.frames = scaffolding + [failing]

    # Stage 3: fields.
    by_number = {m.number: m for m in model.mlog.mutations}
    kept, _ = _minimise_fields(kept_runs, by_number, lambda selection: tester(Job.of(selection, out.frames)),
                               parallel, max_tests=max_tests, say=say, out=out)
    final = tester.answer(Job.of(kept, out.frames))
    out.kept, out.failing_output, out.detail = kept, final.failing_output or failing, final.result.detail
    return out


def minimise_live(tester: LiveTester, mutations: Sequence[Mutation], failure: Failure, full: TestResult,
                  *, say: Say = lambda line: None, max_tests: int | None = None, jobs: int = 1) -> Minimisation:
    """Stages 1 and 3 with whole-system re-runs; ``full`` is the result of the full set, tested already.

    ``jobs`` > 1 tests that many subsets of a round at once, each run an isolated session of the SUT
    (its own router port, run directory and log, as a campaign's cases).
    """
    out = Minimisation(tester=TesterKind.LIVE, failure=failure, mutations=list(mutations), kept={})
    by_number = {m.number: m for m in mutations}
    runs = held_runs(mutations)
    cache = OutcomeCache()
    cache.put(tuple(range(len(runs))), full)  # the reproduction check's answer: not run again
    say(f"stage 1: {len(mutations)} mutations{_runs_note(runs)}, {tester.repeats} run(s) per test"
        + (f", {jobs} tests at once" if jobs > 1 else ""))

    def test_runs(subset: Sequence[Run]) -> TestResult:
        return tester([(by_number[n], None) for n in flatten(subset)])

    first = ddmin(runs, test_runs,
                  DDOptions(parallel=jobs, max_tests=max_tests, progress=_stage_progress(say, "mutations")),
                  cache=cache)
    report = StageReport.of("mutations", "mutations", len(mutations), first, extra_tests=1,
                            note="the full-set reproduction check included" + _runs_note(runs))
    report.after = len(flatten(first.minimal))
    out.stages.append(report)
    last = first.results.get(first.indices) or full
    kept_runs, hold_last = _shorten_holds(first.minimal, test_runs, max_tests, say, out=out, margin=HOLD_MARGIN)
    last = hold_last or last
    kept, fields_last = _minimise_fields(kept_runs, by_number, lambda selection: tester(
        [(by_number[n], s) for n, s in sorted(selection.items())]), jobs, max_tests=max_tests, say=say, out=out)
    last = fields_last or last
    out.kept, out.detail, out.failure_rate = kept, last.detail, last.failure_rate
    return out


def _runs_note(runs: Sequence[Run]) -> str:
    held = [run for run in runs if len(run) > 1]
    if not held:
        return ""
    return f"; {len(runs)} items: {len(held)} held fault(s) of {sum(len(r) for r in held)} messages, each one item"


HOLD_MARGIN = 0.25  # live: a shortened hold of several messages gets this share of its length back at each end


def _shorten_holds(runs: Sequence[Run], test: Callable[[Sequence[Run]], TestResult], max_tests: int | None,
                   say: Say, *, out: Minimisation, margin: float = 0.0) -> tuple[list[Run], TestResult | None]:
    """Stage "hold": each kept held run shortened at its ends with the other runs kept (:func:`.ddmin.shorten`).

    ``margin`` (whole-system re-runs): a hold that needs several messages needs them across the module's
    cycles, whose timing varies from run to run — the shortest hold that failed once sits on that edge
    (seen: a ~24-message hold of a heavy planner's obstacles failed once, not in its confirmation run). It
    gets ``margin`` of its length back at each end (never past the original hold) and is tested once so; if
    that does not fail, the whole hold stays.
    Returns the runs and the result of the last failing test of a shortened set (None: nothing shortened)."""
    kept = list(runs)
    held = [i for i, run in enumerate(kept) if len(run) > 1]
    if not held:
        return kept, None
    started = time.monotonic()
    before = sum(len(kept[i]) for i in held)
    say(f"stage hold: {len(held)} held fault(s) of {before} messages, shortened at their ends")
    tests, complete, last = 0, True, None
    for i in held:
        left = None if max_tests is None else max(max_tests - tests, 0)

        def with_slice(part: Sequence[int], at: int = i) -> TestResult:
            return test([*kept[:at], tuple(part), *kept[at + 1:]])

        result = shorten(kept[i], with_slice, max_tests=left)
        tests += result.tests_run
        complete = complete and result.complete
        chosen = tuple(result.kept)
        if len(chosen) < len(kept[i]):
            last = result.results.get(result.span, last)
            start, stop = result.span
            pad = math.ceil(margin * (stop - start)) if stop - start > 1 else 0
            if pad:
                padded = kept[i][max(0, start - pad):min(len(kept[i]), stop + pad)]
                if len(padded) < len(kept[i]):
                    tests += 1
                    answer = with_slice(padded)
                    chosen, last = (padded, answer) if answer.outcome is Outcome.FAIL else (kept[i], None)
                else:
                    chosen, last = kept[i], None
            say(f"  [hold] {len(kept[i])} → {len(chosen)} messages ({result.tests_run} tests"
                + (f", then {pad} back at each end for the runs' timing" if pad else "") + ")")
        kept[i] = chosen
    out.stages.append(StageReport(name="hold", unit="messages", before=before, after=sum(len(kept[i]) for i in held),
                                  tests_run=tests, cache_hits=0, seconds=time.monotonic() - started, complete=complete,
                                  note="held faults shortened at their ends, never thinned inside"))
    return kept, last


def _minimise_fields(runs: Sequence[Run], by_number: Mapping[int, Mutation],
                     test: Callable[[dict[int, FieldSelection]], TestResult], parallel: int,
                     *, max_tests: int | None, say: Say,
                     out: Minimisation) -> tuple[dict[int, FieldSelection], TestResult | None]:
    """Stage 3: the field changes that matter within the kept mutations that set several — a held run's
    messages keep or revert a field together (they changed the same fields).

    Returns the kept selection and the result of its last test (None if it was not tested here).
    """
    kept: dict[int, FieldSelection] = {n: None for n in flatten(runs)}
    reducible = [r for r, run in enumerate(runs)
                 if by_number[run[0]].fields_reducible and same_fields(run, dict(by_number))]
    items = [(r, i) for r in reducible for i in range(len(by_number[runs[r][0]].fields))]
    if not items:
        out.stages.append(StageReport(name="fields", unit="fields", before=out_fields(kept, by_number),
                                      after=out_fields(kept, by_number),
                                      note="no surviving mutation sets several fields"))
        return kept, None

    def selection(subset: Sequence[tuple[int, int]]) -> dict[int, FieldSelection]:
        chosen: dict[int, FieldSelection] = dict(kept)
        for r in reducible:
            for n in runs[r]:
                chosen[n] = ()  # a reducible mutation's selection starts as (), never None
        for r, i in subset:
            for n in runs[r]:
                chosen[n] = (*(chosen[n] or ()), i)
        return chosen

    say(f"stage 3: {len(items)} field changes in {len(reducible)} mutation(s)")
    before = out_fields(kept, by_number)
    options = DDOptions(parallel=parallel, check_full=False, max_tests=max_tests,
                        progress=_stage_progress(say, "fields"))
    result = ddmin(items, lambda subset: test(selection(subset)), options)
    final = selection(result.minimal)
    report = StageReport.of("fields", "fields", before, result)
    report.after = out_fields(final, by_number)
    out.stages.append(report)
    return final, result.results.get(result.indices)


def out_fields(kept: Mapping[int, FieldSelection], by_number: Mapping[int, Mutation]) -> int:
    return sum(len(by_number[n].fields) if s is None else len(s) for n, s in kept.items())

