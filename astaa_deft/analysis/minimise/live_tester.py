"""The live tester: does a subset of mutations still make the whole system fail?

When the failure is not the planner's output (a control crash or hang, a
speed limit broken in the simulator's status, a NaN command), nothing short
of the whole closed loop can show it. A test then re-runs the SUT through
the star proxy with the test case that pins exactly the subset
(:func:`.restrict.restricted_testcase`), and watches the online monitors:

* FAIL if the failing invariant breaks again (same name and, where the
  violation names one, the same module) — or, for a crash no invariant
  named, the same module exits abnormally;
* PASS if the run reaches the horizon (the original failure's time, or the
  last pinned mutation's, plus a margin, counted from when the pinned
  mutations happened in this run: a stack that starts late sends the pinned
  messages late) without it;
* UNRESOLVED when the run cannot start.

Each run is recorded and judged by the spec's monitors over its log, as
``astaa-deft check`` judges it; the online monitors only end a run early
once they see the failure (a crashed module ends it too), so a failing test
costs little more than the time to the failure.

Whole-system runs are not deterministic (message timing differs between
runs), so each test runs ``repeats`` times and reports the failure rate;
it FAILs if any run failed (a subset that fails only sometimes still holds
the cause), which is what "fails in some runs" means for ddmin here. Runs
are one at a time unless asked (``minimise --jobs N``): two copies of the
SUT on a two-core machine can change the very timing under test. Each run
is its own session (router port, run directory, log), so parallel runs are
isolated as a campaign's cases are; ``run`` is thread-safe. Each run's
recorder is started ahead, while the previous test runs (:meth:`_recorder`).
"""

from __future__ import annotations

import contextlib
import subprocess
import tempfile
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from astaa_deft.model.errors import InputError
from astaa_deft.engine.intercept.dictionary import load_dictionary
from astaa_deft.engine.intercept.engine import Interceptor
from astaa_deft.engine.intercept.testcase import TestCase
from astaa_deft.io.log import layout
from astaa_deft.io.log import records as rec
from astaa_deft.io.log.reader import read_log
from astaa_deft.engine.monitor.offline import CheckResult, check_log
from astaa_deft.engine.monitor.verdict import IMPLICIT
from astaa_deft.engine.session import RunOptions, RunView, run_session
from astaa_deft.engine.session.bus_run import release_warm_recorder, warm_recorder
from astaa_deft.model.sut import Spec
from astaa_deft.analysis.minimise.ddmin import Outcome, TestResult
from astaa_deft.analysis.minimise.failure import Failure
from astaa_deft.analysis.minimise.mutations import FieldSelection, Mutation
from astaa_deft.analysis.minimise.restrict import restricted_testcase, write_testcase
from astaa_deft.model.records import RunMode

MARGIN_SECONDS = 3.0  # a run goes on this long past the original failure (or the last mutation) before it passes
# A run whose pinned mutations have not all happened by the horizon (the stack started late: the pinned
# messages come later) waits this much longer for them before it passes.
PIN_WAIT_SECONDS = 15.0


@dataclass(frozen=True)
class LiveRun:
    failed: bool | None  # None: the run could not tell (it did not start)
    detail: str
    seconds: float
    log: Path | None = None


class LiveTester:
    """Subsets of mutations to whole-system verdicts (module doc)."""

    def __init__(self, spec: Spec, params: Mapping[str, str], failure: Failure, *, repeats: int = 1,
                 original: TestCase | None = None, testcase_id: str = "minimise",
                 progress: Callable[[str], None] = lambda line: None):
        self.spec = spec
        self.params = dict(params)
        self.invariant = failure.invariant
        self.module = failure.module
        self.failure_at = failure.at  # seconds since the run's start in the original log
        self.repeats = max(1, repeats)
        self.original = original
        self.testcase_id = testcase_id
        self.progress = progress
        self.dictionary = load_dictionary()
        self.runs = 0
        self.run_seconds = 0.0
        self._count = threading.Lock()  # tests may run in parallel sessions (--jobs)
        self._anchors: dict[int, tuple[TestCase, float | None]] = {}  # id(testcase) → (it, last pinned at)
        self._recorders: list[subprocess.Popen] = []  # started ahead for the next runs (see _recorder)

    def _recorder(self) -> subprocess.Popen | None:
        """A recorder started ahead (imports done, spec parsed) for this run, and another for the next one.

        A whole-system test waits for its recorder before any module starts:
        starting it ahead saves that wait per test (docs/performance.md,
        "analysis"). None when the spec is not a file.
        """
        if self.spec.path is None:
            return None
        with self._count:
            while self._recorders and self._recorders[0].poll() is not None:
                self._recorders.pop(0)
            taken = self._recorders.pop(0) if self._recorders else None
            with contextlib.suppress(OSError):  # else the next run starts its own
                self._recorders.append(warm_recorder([self.spec.path]))
        return taken

    def close(self) -> None:
        """Let the recorders started ahead go (end of input: they exit)."""
        with self._count:
            recorders, self._recorders = self._recorders, []
        for recorder in recorders:
            release_warm_recorder(recorder)

    def testcase(self, chosen: Sequence[tuple[Mutation, FieldSelection]], description: str = "") -> TestCase:
        testcase = restricted_testcase(chosen, testcase_id=self.testcase_id, description=description,
                                       original=self.original)
        self.pin(testcase, chosen)
        return testcase

    def pin(self, testcase: TestCase, chosen: Sequence[tuple[Mutation, FieldSelection]]) -> None:
        """Remember when ``testcase``'s last pinned mutation happened in the original run (see :meth:`run`)."""
        with self._count:
            self._anchors[id(testcase)] = (testcase, max((m.at for m, _ in chosen), default=None))

    def __call__(self, chosen: Sequence[tuple[Mutation, FieldSelection]]) -> TestResult:
        testcase = self.testcase(chosen)
        horizon = max([self.failure_at] + [m.at for m, _ in chosen]) + MARGIN_SECONDS
        runs = [self.run(testcase, horizon) for _ in range(self.repeats)]
        told = [r for r in runs if r.failed is not None]
        fails = [r for r in told if r.failed]
        rate = len(fails) / len(told) if told else None
        self.progress(f"live test of {len(chosen)} mutation(s): "
                      + ", ".join("fail" if r.failed else "pass" if r.failed is False else "?" for r in runs)
                      + f" ({sum(r.seconds for r in runs):.1f} s)")
        if not told:
            return TestResult(Outcome.UNRESOLVED, runs[0].detail, None)
        if fails:
            return TestResult(Outcome.FAIL, fails[0].detail, rate)
        return TestResult(Outcome.PASS, told[0].detail, rate)

    def run(self, testcase: TestCase, horizon: float, record: Path | None = None,
            policy_file: Path | None = None) -> LiveRun:
        """One whole-system run with ``testcase``: stopped at the failure or at ``horizon`` s.

        Every run is recorded and its verdict is the spec's monitors over
        that log (``check``): the same judgement whatever the online monitors
        could see. The online ones only stop a run early once they report the
        failure (or the module crashes).

        For a test case made by :meth:`testcase` (or given to :meth:`pin`),
        whose last pinned mutation happened at ``anchor`` s in the original
        run: pinned policies hit the N-th message of a channel, which a stack
        that starts late sends later, so the horizon then counts from when the
        last of them happened here (at least ``horizon - anchor`` after it),
        waiting up to PIN_WAIT_SECONDS past the horizon for them to happen.
        """
        with self._count:
            anchor = self._anchors.get(id(testcase), (None, None))[1]
        started = time.monotonic()
        with tempfile.TemporaryDirectory(prefix="astaa-deft-minimise-") as tmp:
            log_path = record or Path(tmp) / "run.mcap"
            policy_file = policy_file or write_testcase(testcase, Path(tmp) / "policy.xml")
            interceptor = Interceptor(testcase, self.spec, self.dictionary) if testcase.policies else None
            options = RunOptions(mode=RunMode.STAR, interceptor=interceptor, record=log_path, params=self.params,
                                 run_dir=Path(tmp) / "run", attachments={layout.POLICY_ATTACHMENT: policy_file},
                                 command_line=["astaa-deft", "minimise"], warm_recorder=self._recorder())
            with self._count:
                self.runs += 1

            wanted = {p.id for p in testcase.policies}
            fired: dict[str, int] = {}  # pinned policy id → when its mutation happened here (ns)

            def on_event(record: rec.Record) -> None:
                if isinstance(record, rec.MutationRecord):
                    for policy in record.policy.split("+"):
                        fired.setdefault(policy, record.time_ns)

            def stop_when(bus: RunView) -> str | None:
                if self._seen_online(bus):
                    return "the failure was seen"
                now = time.time_ns()
                if (now - bus.started_ns) / 1e9 < horizon:
                    return None
                if anchor is None or not wanted:
                    return "horizon"
                happened = [fired.get(p) for p in wanted]
                if None in happened:  # the stack started late: wait for the pinned messages
                    return "horizon (a pinned mutation never happened)" if (
                        now - bus.started_ns) / 1e9 >= horizon + PIN_WAIT_SECONDS else None
                last = max(t for t in happened if t is not None)
                return "horizon" if (now - last) / 1e9 >= horizon - anchor else None

            try:
                run_session(self.spec, options, stop_when=stop_when, on_event=on_event)
            except InputError as exc:
                return LiveRun(None, f"the run did not start: {exc}", time.monotonic() - started)
            finally:
                release_warm_recorder(options.warm_recorder)
            seconds = time.monotonic() - started
            with self._count:
                self.run_seconds += seconds
            try:
                log = read_log(log_path)
                result = check_log(log, self.spec)
            except InputError as exc:
                return LiveRun(None, f"the run's log cannot be judged: {exc}", seconds)
            exits = [e for e in map(rec.decode, log.events("process_exit")) if isinstance(e, rec.ProcessExit)]
            detail = self._matching(result, exits)
            if detail:
                return LiveRun(True, detail, seconds, record)
            return LiveRun(False, result.verdict.summary, seconds, record)

    def _matching(self, result: CheckResult, exits: list[rec.ProcessExit]) -> str:
        """The failure being minimised among a run's findings ('' if it is not there)."""
        if self.invariant == IMPLICIT:  # a crash no invariant named: the module's abnormal exit
            for e in exits:
                if (not e.during_shutdown and (e.returncode or e.signal)
                        and (self.module is None or e.module == self.module)):
                    return e.describe(with_pid=False)
            return ""
        for v in result.violations:
            if v.invariant == self.invariant and (self.module is None or v.module == self.module):
                return f"{v.invariant}: {v.detail}"
        return ""

    def _seen_online(self, bus: RunView) -> bool:
        """Has the run visibly failed already (worth stopping it)?"""
        if any(self.module is None or e.module == self.module for e in bus.crashed()):
            return True
        return any(v.invariant == self.invariant and (self.module is None or v.module == self.module)
                   for v in list(bus.violations))
