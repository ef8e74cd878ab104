"""A bucket's module tests: the frame its module failed on, and whether the suite fails on the defect.

DeFT extracts one frame per recorded output (or trigger) of the module the
spec can replay (the planner, or a ``replay:`` entry), so a cycle in which
the module raised (its node logged the exception and carried on, or died of
it) answered nothing and is in no frame: the suite of such a run passes
although the replayed module would raise. For a crash bucket the frame of
that cycle — the newest trigger the module got before the failure, with the
newest of each other input (an input not heard from yet left absent) — is
added in time order after every frame kept, with no output expected: its
replay raising is the failing module test. The suite is then run once, and
what fails decides whether it fails *on the defect*: an invariant oracle
failing, or (crash bucket) a frame whose replay raises; frames that only
differ from the recording do not count.
"""

from __future__ import annotations

import json
import math
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

from astaa_deft.model.records import Verdict
from astaa_deft.engine.bus import process_launch
from astaa_deft.analysis.deft.export import MANIFEST, export_suite, oracles_of
from astaa_deft.analysis.deft.extract import ExtractedFrame
from astaa_deft.analysis.deft.validator import Comparison
from astaa_deft.analysis.deft.workflow import ExtractReport, run_params
from astaa_deft.io.log import records as rec
from astaa_deft.io.log.reader import LogContents, LoggedMessage, read_log
from astaa_deft.engine.monitor.kinds import invariant_class
from astaa_deft.engine.monitor.verdict import IMPLICIT
from astaa_deft.model.replay_module import ReplayModule
from astaa_deft.model.sut import Spec

_RAISED = re.compile(r"the (?:planner|module) raised (.+)")


@dataclass(frozen=True)
class TestsVerdict:
    fails_on_defect: bool | None  # None: the suite could not run
    detail: str


def is_crash_bucket(verdict: str, invariant: str, spec: Spec) -> bool:
    """Whether a bucket's finding is a module dying or raising (an abnormal exit, a log or exceptions monitor)."""
    if verdict in (Verdict.ABORT, Verdict.CATASTROPHIC) or invariant == IMPLICIT:
        return True
    watched = next((i for i in spec.invariants if i.name == invariant), None)
    return watched is not None and invariant_class(watched.kind).crash_kind


def replayable(spec: Spec, module: str | None) -> bool:
    """Whether the spec can replay ``module`` alone: its planner, or an entry of its ``replay:`` section."""
    if module is None:
        return False
    return (spec.planner is not None and spec.planner.module == module) or any(e.module == module for e in spec.replay)


def add_failure_frame(tests_dir: Path, log_path: Path, spec: Spec, report: ExtractReport, *, invariant: str) -> bool:
    """Add to an extracted suite the frame of the cycle its module failed on (module doc); True if added.

    The module is the one ``report`` replayed (the planner, or a ``replay:``
    entry). The failure is the log's first violation of ``invariant``, else
    the module's first abnormal exit. The failing cycle started on one of
    the triggers between the last frame kept and the failure (the exit is
    seen a little after the cycle died, and triggers go on meanwhile): the
    newest first, each checked by the suite's own replay, the first whose
    replay raises kept (none: the newest). Nothing is added when the log
    does not say when, or no trigger reached the module before it.
    """
    entry = report.entry  # the ReplayModule extracted (the planner's own, or a replay: entry)
    if entry is None:
        return False
    log = read_log(log_path)
    failed_at = next((v.time_ns for v in log.records(rec.Violation) if v.invariant == invariant), None)
    if failed_at is None:
        failed_at = next((e.time_ns for e in log.records(rec.ProcessExit)
                          if e.module == entry.module and e.abnormal), None)
    if failed_at is None:
        return False
    triggers = [m for m in log.on(spec.channel(entry.trigger).key) if m.log_time <= failed_at]
    if not triggers:
        return False
    # Every frame kept (those not reproduced are stepped for their state): the failing cycle's state is the run's.
    kept = list(report.extraction.frames)
    last_kept = max((f.trigger_time for f in kept), default=-1)
    candidates = [m for m in reversed(triggers) if m.log_time > last_kept][:MAX_FAILING_CYCLES] or [triggers[-1]]
    write = _FailureFrameWriter(tests_dir, log, spec, entry)
    for trigger in candidates:
        if write(trigger, kept):
            return True
    write(candidates[0], kept)  # none raised: the newest, its test fails only as a frame that changed
    return True


MAX_FAILING_CYCLES = 8  # triggers tried as the failing cycle's, newest first (each one replay of the suite)


class _FailureFrameWriter:
    """Writes the suite with one candidate failing frame and says whether its replay raises there."""

    def __init__(self, tests_dir: Path, log: LogContents, spec: Spec, entry: ReplayModule) -> None:
        self.tests_dir, self.log, self.spec, self.entry = tests_dir, log, spec, entry
        self.oracles = oracles_of(json.loads((tests_dir / MANIFEST).read_text()))
        self.params = run_params(log, spec)

    def __call__(self, trigger: LoggedMessage, kept: list[ExtractedFrame]) -> bool:
        entry = self.entry
        inputs: dict[str, LoggedMessage] = {entry.trigger: trigger}
        for name in entry.inputs:
            if name != entry.trigger:
                before = [m for m in self.log.on(self.spec.channel(name).key) if m.log_time <= trigger.log_time]
                if before:  # an input not heard from yet (a slow channel) is absent from the frame
                    inputs[name] = before[-1]
        index = max((f.index for f in kept), default=-1) + 1
        failing = ExtractedFrame(index=index, output=None, trigger_time=trigger.log_time, frame_time=trigger.log_time,
            inputs=inputs, comparison=Comparison(distance=math.inf, max_error=math.inf, points=0, how="failed cycle"),
            accepted=True, candidates_tried=0, exact=False)
        frames = sorted([*kept, failing], key=lambda f: f.trigger_time)
        export_suite(frames, self.spec, self.params, self.tests_dir, oracles=self.oracles, entry=entry)
        from astaa_deft.analysis.deft.suite import Suite

        try:
            results = Suite(self.tests_dir).results()
        except Exception:  # a suite that cannot run at all: the campaign's pytest run says why
            return False
        return any(r.index == index and r.error is not None and r.stopped != "not run" for r in results)


def run_module_tests(tests_dir: Path, *, crash: bool, timeout: float = 600.0) -> TestsVerdict:
    """Run the suite once with pytest and judge it (:func:`judge_pytest`)."""
    suite = tests_dir.resolve()  # pytest runs from inside the suite: its own pytest.ini
    try:
        done = process_launch.run([sys.executable, "-m", "pytest", "-q", "-rf", "-p", "no:cacheprovider", str(suite)],
                                  timeout=timeout, cwd=str(suite))
    except subprocess.TimeoutExpired:
        return TestsVerdict(None, f"pytest did not finish in {timeout:.0f} s")
    return judge_pytest(done.returncode, done.stdout + done.stderr, crash=crash)


def judge_pytest(returncode: int, output: str, *, crash: bool) -> TestsVerdict:
    """Whether a suite's pytest run failed on the bucket's defect, from its exit code and output."""
    if returncode == 0:
        return TestsVerdict(False, "they pass on the defect")
    if returncode != 1:
        tail = output.strip().splitlines()[-1:] or [""]
        return TestsVerdict(None, f"pytest exit {returncode}: {tail[0][:200]}")
    failed = [line for line in output.splitlines() if line.startswith("FAILED ")]
    oracle = next((line for line in failed if "::oracle_" in line), None)
    raised = _RAISED.search(output)
    if oracle is not None:
        return TestsVerdict(True, f"its oracle fails: {oracle.split(' - ', 1)[-1][:200]}")
    if raised is not None and crash:
        return TestsVerdict(True, f"the replay raises {raised.group(1).strip()[:200]}")
    if raised is not None:
        return TestsVerdict(False, f"the replay raises {raised.group(1).strip()[:200]}, but the bucket is no crash")
    return TestsVerdict(False, f"{len(failed)} frame(s) differ from the recording; none fails on the defect")
