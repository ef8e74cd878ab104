"""The spec's ``decictor:`` section as typed records (read by ``engine/spec/decictor_section.py``). Pure data."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path



@dataclass(frozen=True)
class TrajectorySection:
    array: str  # the element's array of predicted points
    points: Mapping[str, str]  # point attribute (t, x, y, heading) → field name
    horizon: float = 5.0  # s
    step: float = 0.1  # s


@dataclass(frozen=True, kw_only=True)
class ParticipantMappingSection:
    """How a participant becomes an element of a channel's array field."""

    channel: str
    array: str
    fields: Mapping[str, str]  # participant attribute → element field
    stamp: str | None = None  # the message's time: the clock of the participant's path
    trajectory: TrajectorySection | None = None


@dataclass(frozen=True)
class LanesSection:
    """The ego's lanes: straight lanes from a channel's fields, or a lanes file."""

    channel: str | None = None
    straight: Mapping[str, str] | None = None  # count, width, length → field names
    file: Path | None = None  # resolved against the spec's directory


@dataclass(frozen=True, kw_only=True)
class EgoSection:
    channel: str
    t: str = "header.stamp"
    x: str = "x"
    y: str = "y"
    heading: str = "heading"
    speed: str = "speed"
    acceleration: str = "acceleration"
    length: float = 4.6
    width: float = 1.9


@dataclass(frozen=True)
class FlagSection:
    """A boolean field of a channel (the goal was reached; it collided)."""

    channel: str
    field: str


@dataclass(frozen=True, kw_only=True)
class DecictorSection:
    participants: tuple[ParticipantMappingSection, ...] = ()
    lanes: LanesSection | None = None
    ego: EgoSection | None = None
    goal: FlagSection | None = None
    collision: FlagSection | None = None
    clearance: float | None = None  # m; None: the tool's default
    dt: float | None = None  # s; None: the tool's default
