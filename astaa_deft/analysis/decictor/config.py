"""The spec's ``decictor:`` section: participant mapping, lanes, ego, goal, clearance (docs/decictor.md).

    decictor:
      participants: [...]                 # how a participant maps onto a channel (the participant action)
      lanes:                              # the ego's lanes: from a channel…
        channel: routing
        straight: {count: lane_count, width: lane_width, length: road_length}
      # lanes: {file: lanes.yaml}         # …or a file (next to the spec): lanes: [{id, width, centre: [[x, y], …]}]
      ego: {channel: localization, x: x, y: y, heading: heading, speed: speed, acceleration: acceleration,
            length: 4.6, width: 1.9}      # t: header.stamp unless given
      goal: {channel: status, field: goal_reached}
      collision: {channel: status, field: collision}   # optional
      clearance: 1.5                      # m around the seed path no participant may enter (default 0.5)
      dt: 2.0                             # s between a participant's waypoints (the paper's time step)

The spec loader types the section and checks its shape, with lines
(``astaa_deft.engine.spec.decictor_section``); this asks for the parts a search
needs, each missing one an ``InputError`` naming it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import yaml

from astaa_deft.model.errors import InputError, Problem
from astaa_deft.io.inputfile import LANES, read_input
from astaa_deft.model.fields import FieldPath, get
from astaa_deft.engine.intercept.actions.participant import ChannelMapping, MappingError, read_mappings
from astaa_deft.engine.spec.decictor_section import EgoSection, FlagSection, LanesSection
from astaa_deft.model.sut import Spec
from astaa_deft.analysis.decictor.feasible import DEFAULT_CLEARANCE, DT
from astaa_deft.analysis.decictor.oracle import Lane, straight_lanes

DOCS = "see docs/decictor.md"


@dataclass(frozen=True, kw_only=True)
class DecictorConfig:
    """What a Decictor search needs from the spec, every part present."""

    participants: ChannelMapping  # the channel participants are injected on
    lanes: LanesSection
    ego: EgoSection
    goal: FlagSection
    collision: FlagSection | None
    clearance: float = DEFAULT_CLEARANCE
    dt: float = DT


def _fail(spec: Spec, message: str, fix: str = DOCS) -> InputError:
    return InputError(Problem(str(spec.path or spec.name), None, None, message, fix))


def read_config(spec: Spec) -> DecictorConfig:
    """The section's parts a search needs (the loader checked their shape); one clear error per missing part."""
    section = spec.decictor
    if section is None:
        raise _fail(spec, "the spec has no 'decictor:' section",
                    f"add one with participants, lanes, ego, goal ({DOCS})")
    try:
        mappings = read_mappings(spec)
    except MappingError as exc:
        raise _fail(spec, str(exc), exc.fix) from None
    if section.lanes is None:
        raise _fail(spec, "decictor: no 'lanes': the consistency check needs the ego's lanes",
                    "name them: lanes: {channel: …, straight: {count, width, length}} or lanes: {file: lanes.yaml}")
    if section.lanes.file is not None:
        if not section.lanes.file.is_file():
            raise _fail(spec, f"decictor.lanes.file: no such file {section.lanes.file}",
                        "give a path relative to the spec")
        read_lanes_file(section.lanes.file)  # fails early on a bad file
    if section.ego is None:
        raise _fail(spec, "decictor: no 'ego: {channel: …}': where the ego's pose is published")
    if section.goal is None:
        raise _fail(spec, "decictor: no 'goal: {channel: …, field: …}'",
                    "name the boolean field that says the goal was reached")
    clearance = DEFAULT_CLEARANCE if section.clearance is None else section.clearance
    dt = DT if section.dt is None else section.dt
    return DecictorConfig(participants=next(iter(mappings.values())), lanes=section.lanes, ego=section.ego,
                          goal=section.goal, collision=section.collision, clearance=clearance, dt=dt)


def read_lanes_file(path: Path) -> tuple[Lane, ...]:
    try:
        data = yaml.safe_load(read_input(path, LANES).decode("utf-8"))
        lanes = tuple(Lane(str(item["id"]), tuple((float(x), float(y)) for x, y in item["centre"]),
                           float(item["width"])) for item in data["lanes"])
    except (OSError, yaml.YAMLError, KeyError, TypeError, ValueError) as exc:
        raise InputError(Problem(str(path), None, None, f"not a lanes file: {exc}",
                                 "write lanes: [{id: a, width: 3.5, centre: [[0, 0], [100, 0]]}, …]")) from None
    if not lanes:
        raise InputError(Problem(str(path), None, None, "the lanes file lists no lane", "add at least one lane"))
    return lanes


def lanes_from_message(source: LanesSection, message: dict) -> tuple[Lane, ...]:
    """Straight lanes from the lanes channel's message (count, width, length fields)."""
    assert source.straight is not None
    values = {}
    for key, path in source.straight.items():
        found = get(message, FieldPath.parse(path))
        value = found[0][1] if found else None
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
            raise ValueError(f"lanes channel '{source.channel}': field '{path}' ({key}) is {value!r}")
        values[key] = value
    return straight_lanes(int(values["count"]), float(values["width"]), float(values["length"]))
