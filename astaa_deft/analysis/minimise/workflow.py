"""Minimisation as one library call: ``minimise_log(log, out_dir, options, progress=…) -> MinimiseReport``.

Reads an intercepted run that failed, finds the failure (the named
invariant's first violation, else the run's first), and minimises the run's
mutations to those the failure needs — with the planner replay when the
failure is in the planner's output, else with whole-system re-runs
(docs/minimise.md). The minimal test case is then run live ``confirm``
times to check it reproduces the failure through the proxy.

Without a named invariant, a failure that happens without any of the
mutations (a deadline a loaded machine missed, a bound the stack breaks by
itself) is not what the mutations caused: the minimisation goes on to the
run's next failure — the first violation of the next invariant broken, in
time order — up to FAILURES_TRIED of them, each with its own tester.

This module owns the policy: which tester, the live fallback when the
replay does not reproduce the failure, the reproduction check (flaky or
not), the confirmation runs and the verdict. It prints nothing: progress
lines go to the ``progress`` callback, and the report says what happened;
``astaa-deft minimise`` prints them and picks the exit code, a campaign
may do something else with them.
"""

from __future__ import annotations

import os
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

from astaa_deft.model.errors import InputError, Problem
from astaa_deft.engine.intercept.testcase import TestCase, parse_testcase
from astaa_deft.io.log import layout
from astaa_deft.io.log.reader import LogContents, read_log
from astaa_deft.engine.monitor import with_typed_invariants
from astaa_deft.engine.spec.executes import TRUST_FLAG, what_spec_runs
from astaa_deft.io.output_place import Place, ready_dir, writing
from astaa_deft.analysis.deft.run_metadata import RunMetadata
from astaa_deft.analysis.minimise.anchoring import choose_anchor, pin_to_anchor
from astaa_deft.analysis.minimise.ddmin import FailsWithoutItems, NotReproducible, Outcome, TestResult
from astaa_deft.analysis.minimise.live_tester import MARGIN_SECONDS, LiveRun, LiveTester
from astaa_deft.analysis.minimise.mutations import Mutation, MutationLog, read_mutations
from astaa_deft.analysis.minimise.output import (
    MINIMAL_MCAP,
    TESTS_DIR,
    Confirmation,
    MinimiseSummary,
    copy_log,
    prepare_directory,
    write_module_tests,
    write_replay_log,
    write_summary,
    write_testcase_file,
)
from astaa_deft.analysis.minimise.replay_model import ReplayModel, ReplaySetup, load_spec_for, run_params
from astaa_deft.analysis.minimise.replay_pool import ReplayPool, ReplayUnavailable
from astaa_deft.analysis.minimise.replay_tester import DeftTester, default_setup
from astaa_deft.analysis.minimise.restrict import restricted_testcase
from astaa_deft.analysis.minimise.stages import (
    Failure, Minimisation, TesterChoice, TesterKind, choose_tester, find_failures, minimise_live, minimise_replay,
)
from astaa_deft.model.json import JsonObject, JsonValue
from astaa_deft.model.sut import Spec

FLAKY_CHECK_RUNS = 3  # live runs of the full test case before calling a failure not reproducible
# Failures tried in turn without --invariant while each happens without any of the mutations. Each try
# costs a replay's start or two whole-system runs; a run with more failures the mutations do not cause
# is one its stack or machine fails by itself, reported so rather than searched on.
FAILURES_TRIED = 3

Progress = Callable[[str], None]


@dataclass(frozen=True, kw_only=True)
class MinimiseOptions:
    spec_path: Path | None = None  # None: the spec stored in the log
    invariant: str | None = None  # the failure to keep (None: the run's first violation the mutations cause)
    repeats: int = 1  # whole-SUT re-runs per test when no replay applies
    parallel: int = 2  # tests run at once where the replay allows
    live_only: bool = False  # always re-run the whole SUT
    confirm: int = 3  # live re-runs of the final result
    max_tests: int | None = None  # stop after this many tests and keep the smallest failure
    live_fallback: bool = True  # re-run the SUT when the planner replay does not reproduce the failure
    jobs: int = 1  # whole-system runs at once (live tests, confirmations), each an isolated session
    # Without spec_path: run what the log's own spec names (module commands, replay factories). Off, the
    # workflow refuses and lists them: a log is data (docs/minimise.md, "Logs are data").
    trust_log_spec: bool = False
    spec: Spec | None = None  # spec_path's spec as the calling command loaded it (None: read here, once)

    def check(self) -> None:
        """InputError naming the option when a value makes no sense."""
        if self.repeats < 1:
            raise InputError(Problem("--repeats", None, None, f"{self.repeats} runs per test", "give at least 1"))
        if self.parallel < 1:
            raise InputError(Problem("--parallel", None, None, f"{self.parallel} workers", "give at least 1"))
        if self.jobs < 1:
            raise InputError(Problem("--jobs", None, None, f"{self.jobs} runs at once", "give at least 1"))
        if self.confirm < 0:
            raise InputError(Problem("--confirm", None, None, f"{self.confirm} runs",
                                     "give 0 (no live check) or more"))


@dataclass(kw_only=True)
class MinimiseReport:
    """What a minimisation found: ``reproduced`` is True when the minimal test case stands (exit code 0)."""

    reproduced: bool
    verdict: str
    summary: JsonObject  # as written to DIR/summary.json
    complete: bool = True  # False: stopped before minimising (no mutation needed, not reproducible)
    files: dict[str, Path] = field(default_factory=dict)
    details: MinimiseSummary | None = None  # a complete minimisation's summary, typed

    def text(self) -> str:
        """The closing lines a command prints."""
        return self.details.text() if self.complete and self.details is not None else f"minimise: {self.verdict}"


def minimise_log(log_path: Path, out_dir: Path, options: MinimiseOptions = MinimiseOptions(), *,
                 progress: Progress = lambda line: None) -> MinimiseReport:
    """Minimise the failing intercepted run ``log_path`` into ``out_dir`` (InputError on bad input).

    ``out_dir`` and the temporary directory are checked before the log is
    read; either refusing a write, then or later, raises OutputError.
    """
    options.check()
    place = Place(out_dir, "-o")
    ready_dir(place, temp=True)
    with writing(place), tempfile.TemporaryDirectory(prefix="astaa-deft-minimise-") as scratch:
        return _minimise(log_path, out_dir, options, progress, scratch=Path(scratch))


@dataclass(kw_only=True)
class _Job:
    """One minimisation as its steps share it: the failing run read, the choices made, what was found."""

    log_path: Path
    out_dir: Path
    options: MinimiseOptions
    say: Progress
    scratch: Path  # removed when the minimisation ends
    started: float  # time.monotonic() at the start
    log: LogContents
    spec: Spec
    spec_path: Path | None  # the spec as a file (the log's own, written to scratch, if it came from the log)
    mlog: MutationLog
    failure: Failure
    later: tuple[Failure, ...]  # the run's next failures (no --invariant): tried when this one needs no mutation
    choice: TesterChoice
    params: dict[str, str]  # the spec's params, the run's own over them
    original: TestCase | None  # the logged test case
    notes: list[str] = field(default_factory=list)  # for the summary: why the failure or the tester changed
    model: ReplayModel | None = None  # the replay's model, when the replay minimised
    replays: int = 0
    replay_hits: int = 0

    def stopped(self, message: str, *, notes: list[str] | None = None) -> MinimiseReport:
        return _stopped(self.out_dir, self.failure, self.started, self.log_path, message=message, notes=notes)

    def fall_back_to_live(self, note: str, why: str) -> None:
        """Go on with whole-system re-runs (``note`` says why, to the user and in the summary)."""
        self.say(f"note: {note}")
        self.notes.append(note)
        self.choice = TesterChoice(TesterKind.LIVE, why)


def _minimise(log_path: Path, out_dir: Path, options: MinimiseOptions, say: Progress,
              *, scratch: Path) -> MinimiseReport:
    job = _read_failing_run(log_path, out_dir, options, say, scratch=scratch)
    unneeded: list[tuple[Failure, FailsWithoutItems]] = []  # the failures tried that need no mutation
    while True:
        try:
            return _minimise_failure(job)
        except FailsWithoutItems as exc:
            unneeded.append((job.failure, exc))
            if not job.later:
                return _no_mutation_needed(job, unneeded)
            job = _next_failure(job)


def _next_failure(job: _Job) -> _Job:
    """The job for the run's next failure, once ``job``'s happens without any of the mutations."""
    failure, *later = job.later
    note = (f"{job.failure.invariant} at +{job.failure.at:.2f} s happens without any of the mutations: "
            f"minimising the run's next failure, {failure.describe()}")
    choice = choose_tester(job.spec, failure, job.options.live_only)
    job.say(f"note: {note}")
    job.say(f"tester: {choice.tester.value} ({choice.why})")
    return replace(job, failure=failure, later=tuple(later), choice=choice, notes=[*job.notes, note], model=None,
                   replays=0, replay_hits=0)


def _minimise_failure(job: _Job) -> MinimiseReport:
    """Minimise ``job``'s failure with its tester, confirm and write the result (FailsWithoutItems when the
    failure happens without any of the mutations)."""
    say, options = job.say, job.options
    minimised: Minimisation | None = None
    if job.choice.tester == TesterKind.REPLAY:
        in_replay = _minimise_in_replay(job)
        if isinstance(in_replay, MinimiseReport):
            return in_replay
        minimised = in_replay
    live = LiveTester(job.spec, job.params, job.failure,
                      repeats=options.repeats, original=job.original, testcase_id=f"minimal-{_id(job.original)}",
                      progress=(lambda line: say(f"  {line}")))
    try:
        if job.choice.tester == TesterKind.LIVE:
            in_live = _minimise_live(job, live)
            if isinstance(in_live, MinimiseReport):
                return in_live
            minimised = in_live
        assert minimised is not None
        minimised.notes[:0] = job.notes
        return _confirm_and_write(job, live, minimised)
    finally:
        live.close()  # the recorders started ahead for tests that will not come


def _read_failing_run(log_path: Path, out_dir: Path, options: MinimiseOptions, say: Progress,
                      *, scratch: Path) -> _Job:
    """Read the run, its spec and mutations, find the failure, choose the tester, prepare ``out_dir``
    (InputError when the log cannot be minimised)."""
    started = time.monotonic()
    log = read_log(log_path)
    for warning in log.warnings:
        say(f"warning: {warning}")
    spec, spec_path = _spec_of(log, options, say, scratch)
    recorded_with = RunMetadata.of(log).spec
    if recorded_with and recorded_with != spec.name:
        raise InputError(Problem(str(log_path), None, None,
                                 f"this log was recorded with spec '{recorded_with}', not '{spec.name}'",
                                 "pass the spec the run used"))
    mlog = read_mutations(log, spec)
    if not mlog.mutations:
        reason = ("it was not recorded with a policy (astaa-deft proxy --policy …)"
                  if layout.MUTATIONS_TOPIC not in log.channels
                  else f"its {mlog.noop} mutation event(s) changed nothing")
        raise InputError(Problem(str(log_path), None, None, f"the log holds no mutations: {reason}",
                                 "minimise a run that was intercepted"))
    failure, *later = find_failures(log, spec, options.invariant, most=FAILURES_TRIED)
    prepare_directory(out_dir)
    choice = choose_tester(spec, failure, options.live_only)
    recorded_params = run_params(log)
    if recorded_params:  # they fill the spec's placeholders in the commands that run
        say("the run's params (from the log): " + ", ".join(f"{k}={v}" for k, v in sorted(recorded_params.items())))
    original = original_testcase(log)
    # Live tests pin each mutation counted from the running stack, not from the run's start (anchoring.py).
    anchor = choose_anchor(log, mlog, original)
    mlog = pin_to_anchor(mlog, log, anchor)
    say(f"minimise: {log_path}: {len(mlog.mutations)} mutations; failure: {failure.describe()}")
    if anchor is not None:
        say(f"pinned mutations count from the first '{anchor}' message on (the stack is live then)")
    say(f"tester: {choice.tester.value} ({choice.why})")
    return _Job(log_path=log_path, out_dir=out_dir, options=options, say=say, scratch=scratch, started=started, log=log,
                spec=spec, spec_path=spec_path, mlog=mlog, failure=failure, later=tuple(later), choice=choice,
                params={**spec.params, **recorded_params}, original=original)


def _spec_of(log: LogContents, options: MinimiseOptions, say: Progress, scratch: Path) -> tuple[Spec, Path | None]:
    """(the spec, as a file): ``--spec``'s, or the one stored in the log (when trusted) written to ``scratch``:
    live runs (their recorder) and replays need it as a file."""
    spec_path = options.spec_path
    if options.spec is not None and spec_path is not None:
        return with_typed_invariants(options.spec), spec_path
    spec = with_typed_invariants(load_spec_for(log, str(spec_path) if spec_path else None,
                                               trust_log_spec=options.trust_log_spec))
    if spec.path is None:
        from astaa_deft.engine.spec.loader import load_spec

        runs = what_spec_runs(spec)
        if runs:
            say(f"running what the spec stored in the log names ({TRUST_FLAG}):")
        for item in runs:
            say(f"  {item}")
        spec_path = scratch / "spec.yaml"
        spec_path.write_text(spec.source_text)
        spec = with_typed_invariants(load_spec(spec_path))
    return spec, spec_path


def _minimise_in_replay(job: _Job) -> Minimisation | MinimiseReport | None:
    """The minimisation with the module replay; None: it cannot replay or reproduce the failure, and the job
    falls back to live runs; a report when the minimisation stops here (FailsWithoutItems: the failure
    happens without any of the mutations: raised)."""
    entry, failure, options = job.choice.entry, job.failure, job.options
    assert entry is not None
    setup = default_setup(job.log_path, job.spec_path, failure.invariant)
    if entry.where != "planner":
        setup = replace(setup, module=entry.module, output=entry.output, failure_module=failure.module)
    workers = max(1, min(options.parallel, os.cpu_count() or 1))
    return _replay_with(job, setup, workers)


def _replay_with(job: _Job, setup: ReplaySetup, workers: int) -> Minimisation | MinimiseReport | None:
    """:func:`_minimise_in_replay` on ``setup`` (its outputs paired by their log times, or then by their
    publishers' stamps)."""
    entry, failure, options, say = job.choice.entry, job.failure, job.options, job.say
    assert entry is not None
    try:
        pool = ReplayPool(setup, workers=workers)  # starts the workers: their baseline replay is done
    except ReplayUnavailable as exc:
        if not options.live_fallback:
            return job.stopped(f"{exc} (whole-system re-runs were not tried: --no-live-fallback)")
        job.fall_back_to_live(f"{exc}; whole-system re-runs instead", "the module cannot be replayed here")
        return None
    with pool:
        what = "planner replay" if entry.where == "planner" else f"module replay ({entry.module})"
        say(f"{what}: {pool.workers} worker process(es), one replay of the run in "
            f"{pool.baseline_seconds:.2f} s, per-test timeout {pool.timeout:.0f} s")
        tester = DeftTester(pool)
        model = ReplayModel(setup, baseline=False, spec=job.spec)  # the spec this command loaded
        try:
            result = minimise_replay(tester, model, failure, pool.workers, say=say, max_tests=options.max_tests)
        except NotReproducible as exc:
            job.replays, job.replay_hits = job.replays + tester.runs, job.replay_hits + tester.hits
            late = model.late_outputs() if setup.output_clock == "log" else 0
            if late:  # a loaded recorder logged outputs in bursts: pair them by their publishers' stamps
                say(f"note: the {what} does not reproduce the failure with the outputs paired by their log times "
                    f"({exc}); {late} of {len(model.outputs)} outputs were logged more than "
                    f"{model.cfg.skew_ms:g} ms after their publisher stamped them: paired by those stamps instead")
                retry = replace(setup, output_clock="published")
            elif not options.live_fallback:
                return job.stopped(
                    f"the failure ({failure.invariant}) does not reproduce in the planner replay: {exc} "
                    f"(whole-system re-runs were not tried: --no-live-fallback)")
            else:
                job.fall_back_to_live(f"the planner replay does not reproduce the failure ({exc}); whole-system "
                                      f"re-runs instead", "the replay does not reproduce it")
                return None
        else:
            job.model = model
            job.replays, job.replay_hits = job.replays + tester.runs, job.replay_hits + tester.hits
            return result
    return _replay_with(job, retry, workers)  # this pool's workers are gone by now


def _minimise_live(job: _Job, live: LiveTester) -> Minimisation | MinimiseReport:
    """The minimisation with whole-system re-runs, after checking the full test case reproduces the failure;
    a report when the minimisation stops here (FailsWithoutItems: the failure happens without any of the
    mutations: raised)."""
    failure, options = job.failure, job.options
    full, repeats_used = reproduce(live, job.mlog.mutations, failure, options.repeats, say=job.say)
    if full is None:
        return job.stopped(
            f"the failure ({failure.invariant}) did not reproduce in {live.runs} live re-run(s) of the full "
            f"test case: nothing to minimise (a rare flaky failure? try --repeats N)", notes=job.notes)
    live.repeats = repeats_used
    return minimise_live(live, job.mlog.mutations, failure, full, say=job.say, max_tests=options.max_tests,
                         jobs=options.jobs)


def _confirm_and_write(job: _Job, live: LiveTester, result: Minimisation) -> MinimiseReport:
    """Write the minimal test case, confirm it live, write the log, module tests and summary: the report."""
    out_dir, failure = job.out_dir, job.failure
    testcase = restricted_testcase(
        result.chosen, testcase_id=f"minimal-{_id(job.original)}", original=job.original,
        description=(f"minimised from {job.log_path.name}: {len(result.kept)} of {len(result.mutations)} "
                     f"mutations; fails {failure.invariant}"))
    xml = write_testcase_file(out_dir, testcase, job.spec)
    files = {"test case": xml}
    confirmation, confirm_log = confirm_live(live, testcase, xml, result, options=job.options, say=job.say,
                                             scratch=job.scratch)
    if result.tester == TesterKind.REPLAY and job.model is not None:
        files["log"] = write_replay_log(out_dir / MINIMAL_MCAP, job.model, result, xml)
        files["module tests"] = write_module_tests(out_dir / TESTS_DIR, job.model, result).parent
    elif confirm_log is not None:
        files["log"] = copy_log(confirm_log, out_dir)
    text, reproduced = verdict(result, confirmation)
    files["summary"] = out_dir / "summary.json"
    details = MinimiseSummary(result=result, log=job.log_path, why=job.choice.why,
                              seconds=time.monotonic() - job.started, confirmation=confirmation, verdict=text,
                              files=files, replay_tests=job.replays, replay_hits=job.replay_hits,
                              live_runs=live.runs, live_seconds=live.run_seconds,
                              replayed_module=job.choice.entry.module if job.choice.entry is not None else None)
    body = details.to_json()
    write_summary(out_dir, body)
    return MinimiseReport(reproduced=reproduced, verdict=text, summary=body, files=files, details=details)


def _id(original: TestCase | None) -> str:
    return original.id if original is not None else "run"


def original_testcase(log: LogContents) -> TestCase | None:
    """The logged test case (rates and modes events do not record); None if absent or unreadable."""
    data = log.attachments.get(layout.POLICY_ATTACHMENT)
    if data is None:
        return None
    try:
        return parse_testcase(data, layout.POLICY_ATTACHMENT)
    except InputError:
        return None


def reproduce(live: LiveTester, mutations: Sequence[Mutation], failure: Failure, repeats: int,
              *, say: Progress) -> tuple[TestResult | None, int]:
    """Re-run the full set of mutations: (its result, runs per test from now on); None if it never fails.

    ``repeats`` runs first; if none fails, up to FLAKY_CHECK_RUNS in all
    before giving up. A failure in some runs only is flaky: later tests then
    run at least FLAKY_CHECK_RUNS times each.
    """
    chosen = [(m, None) for m in mutations]
    testcase = live.testcase(chosen)
    horizon = max([failure.at] + [m.at for m in mutations]) + MARGIN_SECONDS
    say(f"reproducing the failure live with all {len(mutations)} mutations pinned")
    runs: list[LiveRun] = []
    while len(runs) < repeats or (len(runs) < FLAKY_CHECK_RUNS and not any(r.failed for r in runs)):
        runs.append(live.run(testcase, horizon))
        say(f"  run {len(runs)}: " + ("fail" if runs[-1].failed else "pass" if runs[-1].failed is False
                                      else f"could not tell ({runs[-1].detail})") + f" ({runs[-1].seconds:.1f} s)")
    told = [r for r in runs if r.failed is not None]
    fails = [r for r in told if r.failed]
    if not fails:
        return None, repeats
    rate = len(fails) / len(told)
    per_test = repeats
    if rate < 1.0:
        per_test = max(repeats, FLAKY_CHECK_RUNS)
        say(f"flaky: the full test case failed in {len(fails)} of {len(told)} runs; "
            f"each test now runs {per_test} times and fails if any run fails")
    return TestResult(Outcome.FAIL, fails[0].detail, rate), per_test


def confirm_live(live: LiveTester, testcase: TestCase, xml: Path, result: Minimisation, *,
                 options: MinimiseOptions, say: Progress, scratch: Path) -> tuple[Confirmation, Path | None]:
    """Run the minimal test case live ``options.confirm`` times (``options.jobs`` at once): its failure rate,
    a failing run's log.

    A whole-system minimisation keeps the log of the first failing run (or
    the last run) in ``scratch``; a replay one records none.
    """
    runs, jobs = options.confirm, options.jobs
    if runs == 0:
        return Confirmation(runs=0, failures=0, rate=None), None
    horizon = max([result.failure.at] + [m.at for m, _ in result.chosen]) + MARGIN_SECONDS
    say(f"confirming {xml.name} live through the proxy ({runs} run(s)" + (f", {jobs} at once)" if jobs > 1 else ")"))
    kept: Path | None = None
    records = [scratch / f"confirm-{n + 1}.mcap" if result.tester == TesterKind.LIVE else None for n in range(runs)]
    with ThreadPoolExecutor(max(1, min(jobs, runs)), thread_name_prefix="confirm") as pool:
        live.pin(testcase, result.chosen)
        outcomes = list(pool.map(lambda record: live.run(testcase, horizon, record=record, policy_file=xml),
                                 records))
    for n, (outcome, record) in enumerate(zip(outcomes, records, strict=True)):
        say(f"  run {n + 1}: " + ("fail" if outcome.failed else "pass" if outcome.failed is False
                                  else f"could not tell ({outcome.detail})") + f" ({outcome.seconds:.1f} s)")
        if record is not None:
            if kept is None and (outcome.failed or n == runs - 1):
                kept = record
            elif record != kept:
                record.unlink(missing_ok=True)
    told = [o for o in outcomes if o.failed is not None]
    failures = sum(1 for o in told if o.failed)
    return Confirmation(runs=len(told), failures=failures, rate=failures / len(told) if told else None,
                        requested=runs, seconds=sum(o.seconds for o in outcomes),
                        details=tuple(sorted({o.detail for o in outcomes if o.failed is not False})[:3])), kept


def verdict(result: Minimisation, confirmation: Confirmation) -> tuple[str, bool]:
    """(the verdict, whether the minimal test case stands: minimised and, where run live, reproduced)."""
    rate = confirmation.rate
    if confirmation.requested and not confirmation.runs:
        return f"minimised, but no confirmation run could tell: {'; '.join(confirmation.details)}", False
    if not confirmation.runs:
        if result.tester == TesterKind.REPLAY:
            return "minimised; reproduced in the planner replay (not run live: --confirm 0)", True
        return "minimised (not confirmed live: --confirm 0)", True
    if rate == 1.0:
        return "minimised and reproduced live in every run", True
    if rate:
        return (f"flaky: the minimal test case fails in {confirmation.failures} of {confirmation.runs} "
                f"live runs ({rate:.0%})"), False
    if result.tester == TesterKind.REPLAY:
        return ("minimised in the planner replay, but the minimal test case did not reproduce the failure live "
                "(the replay is open-loop: see docs/minimise.md)"), False
    return "the minimal test case did not reproduce the failure in its confirmation runs", False


def _no_mutation_needed(job: _Job, unneeded: Sequence[tuple[Failure, FailsWithoutItems]]) -> MinimiseReport:
    """The report when every failure tried happens without any of the mutations: the first one's, naming
    the others."""
    (failure, exc), others = unneeded[0], unneeded[1:]
    message = f"the failure happens without any of the mutations ({exc}): nothing to minimise"
    if others:
        message += ("; so do the run's next failures tried: "
                    + ", ".join(f"{f.invariant} at +{f.at:.2f} s" for f, _ in others))
    return _stopped(job.out_dir, failure, job.started, job.log_path, message=message)


def _stopped(out_dir: Path, failure: Failure, started: float, log_path: Path, *, message: str,
             notes: list[str] | None = None) -> MinimiseReport:
    """A minimisation that ends before minimising: its summary holds the failure and why."""
    body: JsonObject = {"log": str(log_path), "failure": asdict(failure), "verdict": message}
    if notes is not None:
        noted: list[JsonValue] = list(notes)
        body["notes"] = noted
    body["seconds"] = round(time.monotonic() - started, 3)
    write_summary(out_dir, body)
    return MinimiseReport(reproduced=False, verdict=message, summary=body, complete=False)
