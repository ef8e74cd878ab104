"""What an extraction decides: each output's frame and the extraction as a whole.

:class:`ExtractedFrame` (the inputs used, the comparison, accepted or not),
:class:`Decided` (one output as decided, passed on at once: progress,
checkpoints, ``--resume``) and :class:`Extraction` (every frame and the
search's counters, read by the summary and the suite's writer).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

from astaa_deft.analysis.deft.validator import Comparison
from astaa_deft.io.log.reader import LoggedMessage


@dataclass(kw_only=True)
class ExtractedFrame:
    index: int  # 0-based, in output order
    output: LoggedMessage | None  # None: the module answered this frame with nothing (per-trigger frames)
    trigger_time: int
    frame_time: int
    inputs: dict[str, LoggedMessage]  # channel → the message used
    comparison: Comparison
    accepted: bool
    candidates_tried: int
    exact: bool  # the replayed output message equals the recorded one, field for field


InOrder = tuple[int, Comparison | None, bool]  # (frame index, its comparison or None: no output, exact)


@dataclass(frozen=True, kw_only=True)
class Decided:
    """One output as the extraction decided it, passed on as soon as it is (partial results, ``--resume``).

    ``frame`` is None for an output skipped (``skipped`` says why); ``choice``
    names its inputs (channel → index among that channel's messages in the
    log, by log time), which is all a resumed extraction needs to step the
    planner through it again.
    """

    output_index: int
    frame: ExtractedFrame | None
    choice: Mapping[str, int] | None = None
    skipped: str | None = None
    # Frames stepped before ``frame``, cycles that published nothing (no output of their own; their state
    # counts): the suite steps them too. (Not kept for --resume, which steps ``choice`` alone.)
    before: tuple[ExtractedFrame, ...] = ()
    # The suite's own run, done by the replay itself (a forked extraction): frames a fresh module stepped in
    # order — every frame from the first, in the process that made the module — with its judgement of each
    # (frame index, comparison or None for a frame without output, field for field). It covers every frame up
    # to ``frame``; None: it does not, the suite's own run must step them (see SuiteRun).
    in_order: tuple[InOrder, ...] | None = None
    beside: bool = False  # the replay will not do the suite's run (any more): the caller must step every frame


OnOutput = Callable[[int, int, Decided], None]  # (outputs done, outputs in all, the one just decided)


@dataclass(kw_only=True)
class Extraction:
    frames: list[ExtractedFrame] = field(default_factory=list)
    skipped: list[tuple[int, str]] = field(default_factory=list)  # (output index, why)
    outputs: int = 0
    reconstruction_seconds: float = 0.0  # candidate search + decoding the chosen inputs
    validation_seconds: float = 0.0  # reading the recorded and replayed trajectories, comparing them
    planner_seconds: float = 0.0
    warnings: list[str] = field(default_factory=list)
    recorded_outputs: int | None = None  # per-trigger frames: the outputs in the log (``outputs`` counts frames)
    # The candidate search (forked): candidates stopped by the tight per-candidate limit learned from the
    # accepted steps, those run again under the full limit because no other candidate was accepted, and
    # outputs whose kept frame was one of those.
    candidates_cut: int = 0
    cut_retried: int = 0
    retried_kept: int = 0
    capped: int = 0  # outputs not reproduced by their likeliest candidates (the others not tried: see _extract_output)
    reordered: int = 0  # outputs whose candidates were tried in a learned order other than the generic one
    # Cheap outputs whose first candidate the replay process stepped itself, a shadow copy following:
    # accepted, and not (the shadow then searched the others).
    first_stepped_in_runner: int = 0
    first_missed_in_runner: int = 0
    declared: int = 0  # outputs that named the inputs they used (the spec's provenance), tried first
    # Measured at the first output reproduced within 1e-9 but not exactly: how far apart two copies of the
    # module's state answer one frame (0.0: bit for bit); None: not measured.
    copies_differ: float | None = None
    # The suite run once on its own run beside the search (forked extraction): its tests that failed, (frame
    # index, what); None: not run here (the workflow runs the written suite).
    suite_failures: list[tuple[int, str]] | None = None
    # Frames the search judged off on forked copies that the suite's run (a fresh, unforked module) reproduces.
    confirmed_unforked: int = 0
    # The suite's own run done by the replay itself: frames checked by its in-order steps of a fresh module
    # (the replay process that made it stepped them, no fork had taken over); frames the calling process
    # stepped itself (from the first fork that took over on).
    checked_in_replay: int = 0
    checked_beside: int = 0

    def accepted_at(self, threshold: float) -> int:
        return sum(1 for f in self.frames if f.comparison.distance <= threshold)
