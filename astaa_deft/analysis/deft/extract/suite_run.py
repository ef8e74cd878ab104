"""The extracted suite run once on its own run, as `pytest DIR` will: in the replay, or beside the search."""

from __future__ import annotations

from collections.abc import Mapping

from astaa_deft.analysis.deft.extract.judging import Expected, judged, text_of
from astaa_deft.analysis.deft.extract.records import Decided, ExtractedFrame, Extraction, InOrder
from astaa_deft.analysis.deft.replay import ReplayPlanner, trajectory_points
from astaa_deft.analysis.deft.validator import Comparison
from astaa_deft.engine.spec.replay_section import ReplayModule
from astaa_deft.io.codecs.base import Codec, DecodeError


class SuiteRun:
    """The extracted suite run once on its own run: a fresh module stepped on every frame kept, in order, the
    accepted ones compared with their recorded outputs (what `pytest DIR` does), frame by frame as decided.

    The replay process does that run itself while it can (``Decided.in_order``): it made a fresh module and
    steps the kept frames in order in the process that made it, exactly the suite's run, a forked copy holding
    the state from before each output in case its frame is wrong. Once a frame was not so checked (a fork
    took over) this process steps every frame from the first on its own fresh module, beside the search.
    """

    def __init__(self, planner: ReplayPlanner, cfg: ReplayModule, codecs: Mapping[str, Codec]) -> None:
        self.planner, self.cfg, self.codecs = planner, cfg, codecs
        self.frames: list[ExtractedFrame] = []  # every frame decided, in order (index = position)
        self.stepped = 0  # frames this process's module has stepped, from the first
        self.beside = False  # a frame was not checked by the replay: this process steps them all
        self.failing: dict[int, str] = {}  # frame index → what failed
        self.judged: dict[int, tuple[Comparison, bool]] = {}  # frame index → its comparison here, field for field
        self.in_replay = 0  # frames checked by the replay's own in-order steps

    @property
    def failures(self) -> list[tuple[int, str]]:
        """The tests that failed so far: (frame index, what)."""
        return sorted(self.failing.items())

    def add(self, outcome: Decided) -> None:
        if outcome.frame is None:
            return
        self.frames.extend(outcome.before)
        self.frames.append(outcome.frame)
        self.beside = self.beside or outcome.beside
        self._checked(outcome.in_order)

    def _checked(self, in_order: tuple[InOrder, ...] | None) -> None:
        """The replay's own in-order steps of frames (every frame up to the last named was so stepped)."""
        for index, cmp, exact in in_order or ():
            if cmp is not None:
                self._judge(self.frames[index], cmp, exact)
        if in_order:
            self.in_replay = max(self.in_replay, in_order[-1][0] + 1)

    def finish(self, result: Extraction) -> None:
        """After the replay: its last in-order run applied; any frame it did not check, and this process steps
        every frame (the suite's own run, here); then :meth:`settle`."""
        if self.in_replay < len(self.frames):
            self.beside = True
        while self.step_one():
            pass
        self.settle(result)

    def step_one(self) -> bool:
        """Step the next frame decided, if this process runs the suite (False: none waiting)."""
        if not self.beside or self.stepped >= len(self.frames):
            return False
        frame = self.frames[self.stepped]
        self.stepped += 1
        cfg = self.cfg
        try:
            replayed = self.planner.step({name: self.codecs[name].decode(msg.data)
                                          for name, msg in frame.inputs.items()})
        except Exception as exc:  # the module's failure on a frame is a failing test, not ours
            replayed = {"__replay_error__": f"{type(exc).__name__}: {exc}"}
        if frame.output is not None:
            try:
                recorded = self.codecs[cfg.output].decode(frame.output.data)
            except DecodeError:
                recorded = None
            points = trajectory_points(recorded, cfg.trajectory) if cfg.trajectory is not None else []
            self._judge(frame, *judged(cfg, replayed, Expected(recorded, points, text_of(recorded))))
        return self.stepped < len(self.frames)

    def _judge(self, frame: ExtractedFrame, cmp: Comparison, exact: bool) -> None:
        self.judged[frame.index] = (cmp, exact)
        if frame.accepted and not cmp.within(self.cfg.threshold):
            self.failing[frame.index] = f"distance {cmp.distance:.3g} (θ = {self.cfg.threshold:g})"
        else:
            self.failing.pop(frame.index, None)

    def settle(self, result: Extraction) -> None:
        """The suite's own run has the last word on each frame kept: a frame the search judged on forked
        copies a little off (a module not bit-stable across a fork) that the suite's fresh module reproduces
        within θ is a test that passes; one the search accepted but the suite's run does not is a failure
        (``result.suite_failures``: an extraction defect)."""
        result.suite_failures = self.failures
        result.checked_beside = self.stepped
        result.checked_in_replay = 0 if self.beside else self.in_replay
        for frame in result.frames:
            judged = self.judged.get(frame.index)
            if judged is not None and not frame.accepted and judged[0].within(self.cfg.threshold):
                frame.comparison, frame.exact, frame.accepted = judged[0], judged[1], True
                result.confirmed_unforked += 1
