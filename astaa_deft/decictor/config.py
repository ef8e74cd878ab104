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

Every problem is one ``InputError`` naming the spec and the key.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from ..errors import InputError, Problem
from ..fields import FieldPath, get
from ..intercept.actions.participant import ChannelMapping, MappingError, read_mappings
from ..spec.model import Spec
from .feasible import DEFAULT_CLEARANCE, DT
from .oracle import Lane, straight_lanes

DOCS = "see docs/decictor.md"


@dataclass(frozen=True)
class EgoFields:
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
class Flag:
    channel: str
    field: str


@dataclass(frozen=True)
class LanesSource:
    channel: str | None = None
    straight: dict[str, str] | None = None  # count, width, length → field names
    file: Path | None = None


@dataclass(frozen=True)
class DecictorConfig:
    participants: ChannelMapping  # the channel participants are injected on
    lanes: LanesSource
    ego: EgoFields
    goal: Flag
    collision: Flag | None
    clearance: float = DEFAULT_CLEARANCE
    dt: float = DT


def _fail(spec: Spec, message: str, fix: str = DOCS) -> InputError:
    return InputError(Problem(str(spec.path or spec.name), None, None, message, fix))


def read_config(spec: Spec) -> DecictorConfig:
    section = spec.decictor
    if not isinstance(section, dict):
        raise _fail(spec, "the spec has no 'decictor:' section",
                    f"add one with participants, lanes, ego, goal ({DOCS})")
    try:
        mappings = read_mappings(spec)
    except MappingError as exc:
        raise _fail(spec, str(exc), exc.fix) from None
    lanes = section.get("lanes")
    if not lanes:
        raise _fail(spec, "decictor: no 'lanes': the consistency check needs the ego's lanes",
                    "name them: lanes: {channel: …, straight: {count, width, length}} or lanes: {file: lanes.yaml}")
    source = _lanes(spec, lanes)
    ego = section.get("ego")
    if not isinstance(ego, dict) or "channel" not in ego:
        raise _fail(spec, "decictor: no 'ego: {channel: …}': where the ego's pose is published")
    _channel(spec, ego["channel"], "decictor.ego.channel")
    unknown = sorted(set(ego) - set(EgoFields.__dataclass_fields__))
    if unknown:
        raise _fail(spec, f"decictor.ego: unknown key '{unknown[0]}'",
                    "keys: " + ", ".join(EgoFields.__dataclass_fields__))
    sizes = {k: v for k, v in ego.items() if k in ("length", "width")}
    for key, value in sizes.items():
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 < value < 100:
            raise _fail(spec, f"decictor.ego.{key}: {value!r} is not a size in metres", "e.g. length: 4.6")
    names = {k: str(v) for k, v in ego.items() if k not in ("length", "width")}
    ego_fields = EgoFields(**names, **sizes)  # type: ignore[arg-type]
    goal = _flag(spec, section.get("goal"), "goal", required=True)
    assert goal is not None
    collision = _flag(spec, section.get("collision"), "collision", required=False)
    clearance = section.get("clearance", DEFAULT_CLEARANCE)
    dt = section.get("dt", DT)
    for name, value in (("clearance", clearance), ("dt", dt)):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not (0 <= value < 1000) \
                or not math.isfinite(value):
            raise _fail(spec, f"decictor.{name}: {value!r} is not a number of metres/seconds", "e.g. 1.5")
    return DecictorConfig(next(iter(mappings.values())), source, ego_fields, goal, collision, float(clearance),
                          float(dt))


def _channel(spec: Spec, name: Any, where: str) -> str:
    if name not in {c.name for c in spec.channels}:
        raise _fail(spec, f"{where}: unknown channel {name!r}", "channels: " + ", ".join(c.name for c in spec.channels))
    return str(name)


def _flag(spec: Spec, node: Any, key: str, required: bool) -> Flag | None:
    if node is None and not required:
        return None
    if not isinstance(node, dict) or "channel" not in node or "field" not in node:
        raise _fail(spec, f"decictor: no '{key}: {{channel: …, field: …}}'",
                    f"name the boolean field that says {'the goal was reached' if key == 'goal' else 'it collided'}")
    return Flag(_channel(spec, node["channel"], f"decictor.{key}.channel"), str(node["field"]))


def _lanes(spec: Spec, node: Any) -> LanesSource:
    if not isinstance(node, dict):
        raise _fail(spec, "decictor.lanes must be a mapping: {channel: …, straight: …} or {file: …}")
    if "file" in node:
        base = spec.path.parent if spec.path else Path.cwd()
        path = (base / str(node["file"])).resolve()
        if not path.is_file():
            raise _fail(spec, f"decictor.lanes.file: no such file {path}", "give a path relative to the spec")
        read_lanes_file(path)  # fails early on a bad file
        return LanesSource(file=path)
    if "channel" not in node or not isinstance(node.get("straight"), dict):
        raise _fail(spec, "decictor.lanes: needs 'file', or 'channel' with 'straight: {count, width, length}'")
    _channel(spec, node["channel"], "decictor.lanes.channel")
    straight = node["straight"]
    missing = [k for k in ("count", "width", "length") if k not in straight]
    if missing:
        raise _fail(spec, f"decictor.lanes.straight: missing '{missing[0]}'",
                    "name the fields holding the lane count, lane width and road length")
    return LanesSource(channel=str(node["channel"]), straight={k: str(straight[k]) for k in ("count", "width",
                                                                                                "length")})


def read_lanes_file(path: Path) -> tuple[Lane, ...]:
    try:
        data = yaml.safe_load(path.read_text())
        lanes = tuple(Lane(str(item["id"]), tuple((float(x), float(y)) for x, y in item["centre"]),
                           float(item["width"])) for item in data["lanes"])
    except (OSError, yaml.YAMLError, KeyError, TypeError, ValueError) as exc:
        raise InputError(Problem(str(path), None, None, f"not a lanes file: {exc}",
                                 "write lanes: [{id: a, width: 3.5, centre: [[0, 0], [100, 0]]}, …]")) from None
    if not lanes:
        raise InputError(Problem(str(path), None, None, "the lanes file lists no lane", "add at least one lane"))
    return lanes


def lanes_from_message(source: LanesSource, message: dict) -> tuple[Lane, ...]:
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
