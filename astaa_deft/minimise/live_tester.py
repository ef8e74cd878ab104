"""The live tester: does a subset of mutations still make the whole system fail?

When the failure is not the planner's output (a control crash or hang, a
speed limit broken in the simulator's status, a NaN command), nothing short
of the whole closed loop can show it. A test then re-runs the SUT through
the star proxy with the test case that pins exactly the subset
(:func:`.restrict.restricted_testcase`), and watches the online monitors:

* FAIL as soon as the failing invariant breaks again (same name; for a
  process or deadline invariant also the same module) — or, for a crash no
  invariant named, the same module exits abnormally; the run is stopped
  there, so a failing test costs only the time to the failure;
* PASS when the run reaches the horizon (the original failure's time, or
  the last pinned mutation's, plus a margin) without it;
* UNRESOLVED when the run cannot start.

Whole-system runs are not deterministic (message timing differs between
runs), so each test runs ``repeats`` times and reports the failure rate;
it FAILs if any run failed (a subset that fails only sometimes still holds
the cause), which is what "fails in some runs" means for ddmin here. Runs
are one at a time: two copies of the SUT on a two-core machine would change
the very timing under test.
"""

from __future__ import annotations

import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Mapping, Sequence

from ..bus.run import BusRun, RunOptions
from ..errors import InputError
from ..intercept.dictionary import load_dictionary
from ..intercept.engine import Interceptor
from ..intercept.testcase import TestCase
from ..log import layout
from ..monitor.verdict import IMPLICIT
from ..spec.model import Spec
from .ddmin import Outcome, TestResult
from .mutations import FieldSelection, Mutation
from .restrict import restricted_testcase, write_testcase

MARGIN_SECONDS = 3.0  # a run goes on this long past the original failure (or the last mutation) before it passes
POLL_SECONDS = 0.05


@dataclass(frozen=True)
class LiveRun:
    failed: bool | None  # None: the run could not tell (it did not start)
    detail: str
    seconds: float
    log: Path | None = None


class LiveTester:
    """Subsets of mutations to whole-system verdicts (module doc)."""

    def __init__(self, spec: Spec, params: Mapping[str, str], invariant: str, module: str | None, *,
                 failure_at: float, repeats: int = 1, original: TestCase | None = None,
                 testcase_id: str = "minimise", progress: Callable[[str], None] = lambda line: None):
        self.spec = spec
        self.params = dict(params)
        self.invariant = invariant
        self.module = module
        self.failure_at = failure_at  # seconds since the run's start in the original log
        self.repeats = max(1, repeats)
        self.original = original
        self.testcase_id = testcase_id
        self.progress = progress
        self.dictionary = load_dictionary()
        self.runs = 0
        self.run_seconds = 0.0

    def testcase(self, chosen: Sequence[tuple[Mutation, FieldSelection]], description: str = "") -> TestCase:
        return restricted_testcase(chosen, testcase_id=self.testcase_id, description=description,
                                   original=self.original)

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
        """One whole-system run with ``testcase``: stopped at the failure or at ``horizon`` s."""
        started = time.monotonic()
        with tempfile.TemporaryDirectory(prefix="astaa-deft-minimise-") as tmp:
            attachments = {}
            if record is not None:
                policy_file = policy_file or write_testcase(testcase, Path(tmp) / "policy.xml")
                attachments[layout.POLICY_ATTACHMENT] = policy_file
            interceptor = Interceptor(testcase, self.spec, self.dictionary) if testcase.policies else None
            options = RunOptions(mode="star", interceptor=interceptor, record=record, params=self.params,
                                 run_dir=Path(tmp) / "run", attachments=attachments,
                                 command_line=["astaa-deft", "minimise"])
            bus = BusRun(self.spec, options)
            try:
                with bus:
                    while not self._failed(bus):
                        if (time.time_ns() - bus.started_ns) / 1e9 >= horizon:
                            break
                        if bus.launcher is not None and not bus.alive():
                            break
                        time.sleep(POLL_SECONDS)
            except InputError as exc:
                self.runs += 1
                return LiveRun(None, f"the run did not start: {exc}", time.monotonic() - started)
            seconds = time.monotonic() - started
            self.runs += 1
            self.run_seconds += seconds
            detail = self._failed(bus)  # also what only the end of the run decided
            if detail:
                return LiveRun(True, detail, seconds, record)
            return LiveRun(False, bus.verdict.summary if bus.verdict is not None else "", seconds, record)

    def _failed(self, bus: BusRun) -> str:
        """The matching failure seen so far in ``bus`` ('' if none)."""
        if self.invariant == IMPLICIT:
            for exit_ in bus.crashed():
                if self.module is None or exit_.module == self.module:
                    return f"{exit_.describe()}"
            return ""
        for v in list(bus.violations):
            if v.get("invariant") == self.invariant and (self.module is None or v.get("module") == self.module):
                return f"{v.get('invariant')}: {v.get('detail')}"
        return ""
