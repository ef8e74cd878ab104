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

PER_OUTPUT = "per_output"  # one frame per recorded output, found by DeFT's candidate search (the planner's)
PER_TRIGGER = "per_trigger"  # one frame per trigger message; the module answers with one output or none
FRAME_MODES = (PER_TRIGGER, PER_OUTPUT)
EXCEPTIONS = ("unresolved", "crash")


@dataclass(frozen=True)
class TrajectoryLayout:
    points: str = "points"  # field path of the array of points in the output message
    x: str = "x"
    y: str = "y"
    t: str = "t"
    heading: str = "heading"  # used by the collision oracle only
    time: str = "absolute"  # "absolute" (the bus clock, s) or "relative" to `stamp`
    stamp: str = "header.stamp"


@dataclass(frozen=True)
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


@dataclass(frozen=True)
class ReplayModule:
    """A module that runs alone on reconstructed frames: what it reads, answers, and how to run it."""

    module: str
    inputs: tuple[str, ...]  # channel names, the trigger among them
    trigger: str
    output: str
    factory: str | None = None  # "package.module:Name": in-process replay
    factory_args: Mapping[str, str] = field(default_factory=dict)
    command: tuple[str, ...] = ()  # or: the module's own process, fed in lock-step over Zenoh
    frames: str = PER_TRIGGER
    # What an exception from step() means: "crash" (the module's own process would die of it: the replay
    # shows a crash) or "unresolved" (the real module may never let such input reach the replayed code).
    exceptions: str = "unresolved"
    hang_after: float = 1.0  # s: a step still running then is a hang (the module answers nothing more)
    threshold: float = 0.0
    lookback_ms: float = 100.0
    skew_ms: float = 5.0
    ignore: tuple[str, ...] = ()  # dotted output field paths the comparison skips
    trajectory: TrajectoryLayout | None = None  # outputs compared as trajectories (the planner) …
    collision: CollisionOracle | None = None  # … with its collision oracle
    where: str = "replay.modules"  # the spec section it came from (for messages)

    @property
    def per_trigger(self) -> bool:
        return self.frames == PER_TRIGGER
