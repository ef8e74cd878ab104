"""The state one extraction's steps share: the module, its recorded traffic, what the search learned so far."""

from __future__ import annotations

import os
from dataclasses import dataclass, field

from astaa_deft.analysis.deft.extract.judging import Judged
from astaa_deft.analysis.deft.extract.recorded import Recorded
from astaa_deft.analysis.deft.extract.records import Decided, ExtractedFrame, Extraction, InOrder, OnOutput
from astaa_deft.analysis.deft.extract.speculation import Speculation
from astaa_deft.analysis.deft.fork_replay import (
    ForkedSearch,
)
from astaa_deft.analysis.deft.frames import Candidate
from astaa_deft.analysis.deft.replay import ReplayPlanner
from astaa_deft.analysis.deft.search_policy import SearchMemory
from astaa_deft.analysis.deft.validator import Comparison
from astaa_deft.engine.spec.replay_section import ReplayModule


@dataclass(kw_only=True)
class Run:
    """The state the steps of one extraction (:func:`extract_in_order`) share, in the process that carries it on."""

    planner: ReplayPlanner
    cfg: ReplayModule
    recorded: Recorded
    search: ForkedSearch | None  # None: candidates stepped here from deep copies of the state
    progress: OnOutput
    result: Extraction
    previous: dict[str, int] = field(default_factory=dict)  # the choice kept for the output before
    memory: SearchMemory = field(default_factory=SearchMemory)  # how earlier kept frames were derived, their time
    speculation: Speculation = field(default_factory=lambda: Speculation())
    last_step_s: float | None = None  # the CPU time of the last accepted step: a cycle's measured cost
    misses_in_row: int = 0  # outputs kept just before this one that no candidate reproduced (forked search)
    # The suite's own run done by the replay (see SuiteRun): ``born`` is the process that made ``planner``
    # fresh and stepped it on every frame kept, in order (None: no such process — the caller runs the suite).
    born: int | None = None

    def report(self, out_index: int, skipped: str | None = None, silent: int = 0) -> None:
        """Pass on the output just decided (its frame is the last one, after ``silent`` frames of cycles that
        published nothing; ``skipped``: none, and why).

        A shadow following the runner reports nothing: the runner does.
        """
        if skipped is not None:
            self.result.skipped.append((out_index, skipped))
        frame = self.result.frames[-1] if skipped is None else None
        before = tuple(self.result.frames[-1 - silent:-1]) if silent and frame is not None else ()
        if self.speculation.following is None:
            index_of = self.recorded.index_of
            in_order = self.in_order(len(before) + 1) if frame is not None else None
            self.progress(out_index + 1, len(self.recorded.outputs), Decided(
                output_index=out_index, frame=frame, choice=None if frame is None else {
                    name: index_of[name][id(msg)] for name, msg in frame.inputs.items()}, skipped=skipped,
                before=before, in_order=in_order, beside=self.born is None))

    def keep(self, out_index: int, cand: Candidate, judged: Judged) -> None:
        """Record ``cand`` as the frame of output ``out_index`` and report it."""
        self.previous = dict(cand.choice)
        recorded, cfg = self.recorded, self.cfg
        for silent in cand.silent:  # cycles that published nothing, stepped first: in the suite for their state
            self.result.frames.append(ExtractedFrame(
                index=len(self.result.frames), output=None,
                trigger_time=recorded.streams[cfg.trigger].times[silent[cfg.trigger]],
                frame_time=recorded.streams[cfg.trigger].times[silent[cfg.trigger]],
                inputs={name: recorded.messages[name][idx] for name, idx in silent.items()},
                comparison=Comparison(0.0, 0.0, 0, "silent"), accepted=False, candidates_tried=0, exact=False))
        self.result.frames.append(ExtractedFrame(
            index=len(self.result.frames), output=recorded.outputs[out_index],
            trigger_time=recorded.streams[cfg.trigger].times[cand.choice[cfg.trigger]], frame_time=cand.frame_time,
            inputs={name: recorded.messages[name][idx] for name, idx in cand.choice.items()},
            comparison=judged.comparison, accepted=judged.comparison.within(cfg.threshold),
            candidates_tried=judged.tries, exact=judged.exact))
        self.report(out_index, silent=len(cand.silent))

    def in_order(self, new: int) -> tuple[InOrder, ...] | None:
        """The suite's run of the ``new`` frames just kept, if this process did it (see Decided.in_order).

        In the process that made the module, stepping every frame kept in order, they were judged as the
        suite judges them. Once a fork took over (the kept frame was not the first candidate this process
        stepped), its module is a copy, not one made where it runs (a module may answer otherwise in a forked
        process), and the caller steps the suite beside from then on: stepping every frame again here on a
        fresh module would lengthen the search by as many steps (measured on the zoo: 10-45 % of the
        extraction's time), while the caller's run uses a core the search mostly leaves idle.
        """
        if self.born is not None and self.born != os.getpid():
            self.born = None
        if self.born is None:
            return None
        return tuple((f.index, f.comparison if f.output is not None else None, f.exact)
                     for f in self.result.frames[-new:])
