"""The records of a planner replay test: what a test asks (:class:`Job`), what it answers
(:class:`ReplayAnswer`), what a worker builds its model from (:class:`ReplaySetup`), and a
:class:`Frame`. They cross the pipes to the replay workers pickled (:mod:`.replay_pool`)."""

from __future__ import annotations

from collections.abc import Hashable, Mapping, Sequence
from dataclasses import dataclass

from astaa_deft.analysis.minimise.ddmin import TestResult
from astaa_deft.analysis.minimise.mutations import Delivered, FieldSelection


@dataclass(frozen=True)
class Job:
    """One test: the kept mutations (number → field selection) and, for stage 2, the frames replayed.

    ``frames`` None: every output's frame, continuing from the baseline's
    snapshots. A tuple of output indices: only those frames, in order, from a
    fresh planner (the scaffolding search).
    """

    kept: tuple[tuple[int, FieldSelection], ...]
    frames: tuple[int, ...] | None = None

    @classmethod
    def of(cls, kept: Mapping[int, FieldSelection], frames: Sequence[int] | None = None) -> Job:
        return cls(tuple(sorted(kept.items())), None if frames is None else tuple(sorted(frames)))


@dataclass(frozen=True)
class ReplayAnswer:
    result: TestResult
    failing_output: int | None = None  # index of the output whose replay broke the invariant


@dataclass(frozen=True, kw_only=True)
class ReplaySetup:
    """What a worker needs to build its own :class:`ReplayModel` (plain, picklable data)."""

    log_path: str
    spec_path: str | None  # None: the spec stored in the log, used only with trust_log_spec
    invariant: str
    module: str | None = None  # the replayed module (None: whichever entry can judge the failure)
    output: str | None = None  # its output (a module may have one entry per output)
    failure_module: str | None = None  # the module the failure names (a crash is judged for it only)
    trust_log_spec: bool = False  # the user let the log's own spec run (--trust-log-spec)
    # Which trigger an output answered, by its log time ("log") or by its publisher's stamp ("published": a
    # loaded recorder logs outputs in bursts, long after they were published).
    output_clock: str = "log"


@dataclass(frozen=True)
class Frame:
    output: int  # index into the recorded outputs (per-trigger modules: into the trigger messages)
    inputs: tuple[tuple[str, Delivered], ...]
    frame_time_ns: int
    trigger_time_ns: int

    @property
    def key(self) -> tuple[Hashable, ...]:
        return tuple(d.key for _, d in self.inputs)
