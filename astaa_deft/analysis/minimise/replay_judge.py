"""How one planner replay test is judged: the module's outputs fed to the failing invariant's monitor.

A :class:`ReplayJudge` holds one test's ``MonitorSet`` (only the judged
invariant) and turns each replayed step — an output, a hang, an exception —
into the test's answer: FAIL at the first violation, UNRESOLVED when the
module cannot be judged, PASS when the run's end is reached cleanly.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

from astaa_deft.analysis.deft.replay import ReplayPlanner, StepHang
from astaa_deft.analysis.minimise.ddmin import Outcome, TestResult
from astaa_deft.analysis.minimise.replay_records import Frame, ReplayAnswer
from astaa_deft.engine.monitor import MonitorSet, format_violation
from astaa_deft.engine.monitor.base import ReplayJudges
from astaa_deft.engine.monitor.kinds import invariant_class
from astaa_deft.model.json import DecodedMessage

if TYPE_CHECKING:
    from astaa_deft.analysis.minimise.replay_model import ReplayModel


class ReplayJudge:
    """One test's judging of ``model``'s replayed outputs (a fresh monitor set per test)."""

    def __init__(self, model: ReplayModel) -> None:
        self.model = model
        self.monitors = MonitorSet(model.judged, model.start_ns)

    def silence(self, rest: Sequence[Frame | None], stopped_at: int) -> ReplayAnswer:
        """The module crashed or hangs on frame ``stopped_at``: it answers nothing more; the clock goes on.

        A failure that follows (a deadline) is the stopping frame's: that is the frame a history is kept for.
        """
        why = f"module '{self.model.cfg.module}' silent since trigger {stopped_at}"
        for frame in rest:
            if frame is not None:
                found = self.monitors.on_tick(self.model.output_time(frame))
                if found:
                    return ReplayAnswer(TestResult(Outcome.FAIL, f"{format_violation(found[0], self.model.start_ns)} "
                                                                 f"({why})"), stopped_at)
        answer = self.finish()
        if answer.result.outcome is Outcome.FAIL:
            return ReplayAnswer(TestResult(Outcome.FAIL, f"{answer.result.detail} ({why})"), stopped_at)
        return answer

    def feed(self, frame: Frame, message: DecodedMessage | None) -> str | None:
        """``frame``'s output ``message`` judged at its time: the first violation's text, or None."""
        model = self.model
        time_ns = model.output_time(frame)
        found = self.monitors.on_tick(time_ns)
        if model.cfg.per_trigger:
            if not found and message is not None:  # None: the module answered this frame with nothing
                found = self.monitors.on_message(model.cfg.output, time_ns, message, model.output_sequence(frame))
        else:
            found = self.monitors.on_message(model.cfg.output, time_ns, message, model.output_sequence(frame))
        if found:
            return f"{format_violation(found[0], self.model.start_ns)} (output {frame.output})"
        return None

    def judge(self, planner: ReplayPlanner, frames: Sequence[Frame]) -> ReplayAnswer:
        """Replay ``frames`` in order on ``planner`` and judge every output."""
        try:
            for n, frame in enumerate(frames):
                answer = self.judged_step(planner, frame)
                if answer is STOPPED:
                    return self.silence(frames[n + 1:], frame.output)
                if answer is not None:
                    return answer
        finally:
            planner.close()
        return self.finish()

    def judge_last(self, planner: ReplayPlanner, frames: Sequence[Frame]) -> ReplayAnswer:
        """A per-trigger module's scaffolding test: the history steps unjudged, then the last frame is judged.

        Judging the history's outputs would be wrong here: a few kept frames
        are seconds apart, which a deadline reads as silence. What is asked is
        whether the last frame fails as in the run: it hangs (a deadline
        failure), crashes, or its output breaks the invariant.
        """
        try:
            for frame in frames[:-1]:
                try:
                    self.model.step(planner, frame)
                except Exception as exc:  # StepHang included: the module stopped before the failing frame
                    return ReplayAnswer(TestResult(Outcome.UNRESOLVED, f"module '{self.model.cfg.module}' stopped on "
                                                                       f"trigger {frame.output}: {exc}"))
            if not frames:
                return ReplayAnswer(TestResult(Outcome.PASS))
            last = frames[-1]
            try:
                message = self.model.step(planner, last)
            except StepHang as exc:
                # A module that never answers again: the silence a timing invariant watches for.
                if any(invariant_class(i.kind).replay_judges is ReplayJudges.TIMING
                       for i in self.model.judged.invariants):
                    return ReplayAnswer(TestResult(Outcome.FAIL, f"module '{self.model.cfg.module}' hangs on trigger "
                                                                 f"{last.output}: {exc}"), last.output)
                return ReplayAnswer(TestResult(Outcome.PASS))
            except Exception as exc:
                if self.model.cfg.exceptions != "crash":
                    return ReplayAnswer(TestResult(Outcome.UNRESOLVED, f"module '{self.model.cfg.module}' raised "
                                                                       f"{type(exc).__name__}: {exc}"))
                answer = self.crashed(last, exc)
                return answer if answer is not STOPPED else ReplayAnswer(TestResult(Outcome.PASS))
            found = self.feed(last, message)
            return ReplayAnswer(TestResult(Outcome.FAIL, found), last.output) if found else ReplayAnswer(
                TestResult(Outcome.PASS))
        finally:
            planner.close()

    def judged_step(self, planner: ReplayPlanner, frame: Frame) -> ReplayAnswer | None:
        """One replayed output, judged: an answer if it decides the test, else None.

        A per-trigger module that hangs, or raises where its process would
        die (``exceptions: crash``), answers ``STOPPED`` unless that decides
        the test (a crash the failure is): it answers nothing more.
        """
        try:
            message = self.model.step(planner, frame)
        except StepHang as exc:
            if self.model.cfg.per_trigger:
                return STOPPED
            return ReplayAnswer(TestResult(Outcome.UNRESOLVED, f"the planner hangs on output {frame.output}'s frame: "
                                                               f"{exc}"))
        except Exception as exc:
            if self.model.cfg.per_trigger and self.model.cfg.exceptions == "crash":
                return self.crashed(frame, exc)
            who = "the planner" if self.model.cfg.where == "planner" else f"module '{self.model.cfg.module}'"
            return ReplayAnswer(TestResult(Outcome.UNRESOLVED, f"{who} raised {type(exc).__name__}: {exc} "
                                                               f"on output {frame.output}'s frame"))
        found = self.feed(frame, message)
        return ReplayAnswer(TestResult(Outcome.FAIL, found), frame.output) if found else None

    def crashed(self, frame: Frame, exc: Exception) -> ReplayAnswer:
        """The module's process would die of ``exc``: its abnormal exit, judged like the run's."""
        what = f"module '{self.model.cfg.module}' crashes on trigger {frame.output}: {type(exc).__name__}: {exc}"
        time_ns = self.model.output_time(frame)
        found = self.monitors.on_process_exit(self.model.cfg.module, 1, None, time_ns, during_shutdown=False)
        if found:
            return ReplayAnswer(TestResult(Outcome.FAIL, f"{format_violation(found[0], self.model.start_ns)} ({what})"),
                                frame.output)
        if self.model.crash_fails and self.model.failure_module == self.model.cfg.module:
            return ReplayAnswer(TestResult(Outcome.FAIL, what), frame.output)
        return STOPPED

    def finish(self) -> ReplayAnswer:
        found = self.monitors.finish(self.model.end_ns)
        if found:
            return ReplayAnswer(TestResult(Outcome.FAIL, format_violation(found[0], self.model.start_ns)))
        return ReplayAnswer(TestResult(Outcome.PASS))


# A per-trigger module that crashed or hangs: no answer decided the test, and it answers nothing more.
STOPPED = ReplayAnswer(TestResult(Outcome.UNRESOLVED, "the module stopped answering"))
