"""What a module that can run alone is: the typed records both spec sections load into.

The ``planner:`` section and each entry of ``replay: modules:`` describe the
same thing — a module, its inputs and trigger, its output, how to run it
alone — and load into one :class:`ReplayModule`; the planner's entry adds
its extras (frames found per output by DeFT's candidate search, outputs
compared as trajectories, an optional collision oracle). Pure data.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from astaa_deft.model.vocabulary import TextEnum


class SpecWord(TextEnum):
    """A word of the spec's vocabulary: compares, prints and serialises as the text the spec writes."""


class FrameMode(SpecWord):
    """How the frames a module replays are found (``frames:``)."""

    PER_TRIGGER = "per_trigger"  # one frame per trigger message; the module answers with one output or none
    PER_OUTPUT = "per_output"  # one frame per recorded output, found by DeFT's candidate search (the planner's)


class StepExceptions(SpecWord):
    """What an exception from a replayed ``step()`` means (``exceptions:``)."""

    # The real module may never let such input reach the replayed code: the frame stays undecided.
    UNRESOLVED = "unresolved"
    CRASH = "crash"  # the module's own process would die of it: the replay shows a crash


PER_OUTPUT = FrameMode.PER_OUTPUT
PER_TRIGGER = FrameMode.PER_TRIGGER
FRAME_MODES = tuple(mode.value for mode in FrameMode)  # the first is the default
EXCEPTIONS = tuple(meaning.value for meaning in StepExceptions)  # the first is the default


@dataclass(frozen=True, kw_only=True)
class TrajectoryLayout:
    points: str = "points"  # field path of the array of points in the output message
    x: str = "x"
    y: str = "y"
    t: str = "t"
    heading: str = "heading"  # used by the collision oracle only
    time: str = "absolute"  # "absolute" (the bus clock, s) or "relative" to `stamp`
    stamp: str = "header.stamp"


@dataclass(frozen=True, kw_only=True)
class CollisionOracle:
    """A planned pose that, reached at its planned time, overlaps an obstacle as predicted in that frame."""

    ego_length: float
    ego_width: float
    channel: str  # the input holding predicted obstacles
    array: str = "obstacles"
    length: str = "length"
    width: str = "width"
    id: str = "id"
    trajectory: str = "trajectory"  # each obstacle's predicted poses: {t, x, y, heading}
    margin: float = 0.0


@dataclass(frozen=True, kw_only=True)
class ReplayModule:
    """A module that runs alone on reconstructed frames: what it reads, answers, and how to run it."""

    module: str
    inputs: tuple[str, ...]  # channel names, the trigger among them
    trigger: str
    output: str
    factory: str | None = None  # "package.module:Name": in-process replay
    factory_args: Mapping[str, str] = field(default_factory=dict)
    command: tuple[str, ...] = ()  # or: the module's own process, fed in lock-step over Zenoh
    frames: FrameMode = FrameMode.PER_TRIGGER
    exceptions: StepExceptions = StepExceptions.UNRESOLVED
    hang_after: float = 1.0  # s: a step still running then is a hang (the module answers nothing more)
    threshold: float = 0.0
    lookback_ms: float = 100.0
    skew_ms: float = 5.0
    ignore: tuple[str, ...] = ()  # dotted output field paths the comparison skips
    trajectory: TrajectoryLayout | None = None  # outputs compared as trajectories (the planner) …
    collision: CollisionOracle | None = None  # … with its collision oracle
    where: str = "replay.modules"  # the spec section it came from (for messages)
    # Where the module's output names the inputs it used (a field path to {input channel: its header.seq or
    # header.stamp}): that frame is tried first, checked by replay like any other.
    provenance: str | None = None

    @property
    def per_trigger(self) -> bool:
        """One frame per trigger message (not per recorded output)."""
        return self.frames == PER_TRIGGER
