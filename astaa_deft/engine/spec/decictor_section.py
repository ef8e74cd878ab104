"""The spec's ``decictor:`` section as typed records (docs/decictor.md).

```yaml
decictor:
  participants:                     # how a participant maps onto a channel (the participant action)
    - {channel: prediction, array: obstacles, stamp: header.stamp,
       fields: {id: id, kind: kind, length: length, width: width},
       trajectory: {array: trajectory, t: t, x: x, y: y, heading: heading, horizon: 5.0, step: 0.1}}
  lanes: {channel: routing, straight: {count: lane_count, width: lane_width, length: road_length}}
  # lanes: {file: lanes.yaml}       # or a file next to the spec
  ego: {channel: localization, x: x, y: y, heading: heading, speed: speed, acceleration: acceleration,
        length: 4.6, width: 1.9}
  goal: {channel: status, field: goal_reached}
  collision: {channel: status, field: collision}   # optional
  clearance: 1.5                    # m (default: Decictor's 0.5)
  dt: 2.0                           # s between a participant's waypoints
```

The loader checks the section's shape here, with the file, line and a fix
for each problem: keys, value kinds, numbers, channel names, field-path
syntax. Every part is optional at load time — the participant action needs
only ``participants`` — and what a use needs is asked for by that use:
``astaa_deft.engine.intercept.actions.participant.read_mappings`` checks the mapped
fields against the channel's type; ``astaa_deft.analysis.decictor.config`` requires
lanes, ego and goal ("the consistency check needs the ego's lanes").
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path
from typing import Any

from astaa_deft.model.errors import did_you_mean
from astaa_deft.model.fields import FieldPath, FieldPathError
from astaa_deft.io.yamlsource import Node, Source, describe_value
from astaa_deft.model.decictor import (
    DecictorSection, EgoSection, FlagSection, LanesSection, ParticipantMappingSection, TrajectorySection,
)

SECTION_KEYS = ("participants", "lanes", "ego", "goal", "collision", "clearance", "dt")
MAPPING_KEYS = ("channel", "array", "stamp", "fields", "trajectory")
PARTICIPANT_ATTRIBUTES = ("id", "kind", "x", "y", "heading", "vx", "vy", "speed", "length", "width")
POINT_ATTRIBUTES = ("t", "x", "y", "heading")
TRAJECTORY_KEYS = ("array", *POINT_ATTRIBUTES, "horizon", "step")
MAX_TRAJECTORY_POINTS = 1000
STRAIGHT_KEYS = ("count", "width", "length")
EGO_FIELDS = ("t", "x", "y", "heading", "speed", "acceleration")
EGO_SIZES = ("length", "width")
FLAG_KEYS = ("channel", "field")
DOCS = "see docs/decictor.md"


class _Reader:
    def __init__(self, src: Source, channels: tuple[str, ...], base_dir: Path):
        self.src = src
        self.channels = channels
        self.base_dir = base_dir

    def mapping(self, node: Node, allowed: tuple[str, ...], where: str, example: str) -> bool:
        if not node.is_map:
            self.src.at(node, f"{where} must be a mapping, not {describe_value(node.value)}", f"e.g. {example}")
            return False
        for key in node.value:
            if key not in allowed:
                self.src.at_key(node, key, f"unknown key '{key}' in {where}",
                                did_you_mean(key, allowed) or f"keys: {', '.join(allowed)}")
        return True

    def required(self, node: Node, keys: tuple[str, ...], where: str) -> bool:
        missing = [k for k in keys if k not in node.value]
        for key in missing:
            self.src.at(node, f"{where}: missing '{key}'", f"add '{key}: …' ({DOCS})")
        return not missing

    def text(self, node: Node, where: str) -> str | None:
        if isinstance(node.value, bool) or not isinstance(node.value, (str, int)) or node.value == "":
            self.src.at(node, f"{where} must be a name, not {describe_value(node.value)}", DOCS)
            return None
        return str(node.value)

    def path(self, node: Node, where: str) -> str | None:
        text = self.text(node, where)
        if text is None:
            return None
        try:
            FieldPath.parse(text)
        except FieldPathError as exc:
            self.src.at(node, f"{where}: invalid field path {text!r}: {exc.reason}", "e.g. header.stamp")
            return None
        return text

    def channel(self, node: Node, where: str) -> str | None:
        name = self.text(node, where)
        if name is not None and name not in self.channels:
            self.src.at(node, f"{where}: unknown channel '{name}'",
                        did_you_mean(name, self.channels) or "channels: " + ", ".join(self.channels))
            return None
        return name

    def number(self, node: Node, where: str, low: float, high: float, *, example: str) -> float | None:
        value = node.value
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
                or not low <= value <= high:
            self.src.at(node, f"{where} must be a number from {low:g} to {high:g}, not {describe_value(value)}",
                        f"e.g. {example}")
            return None
        return float(value)

    def field_map(self, node: Node, allowed: tuple[str, ...], where: str) -> dict[str, str] | None:
        if not node.is_map or not node.value:
            self.src.at(node, f"{where} must map attributes ({', '.join(allowed)}) to field names",
                        "e.g. {id: id, x: x, y: y}")
            return None
        out = {}
        for key, value in node.items():
            if key not in allowed:
                self.src.at_key(node, key, f"{where}: '{key}' is not a participant attribute",
                                did_you_mean(key, allowed) or "use: " + ", ".join(allowed))
                continue
            text = self.path(value, f"{where}.{key}")
            if text is not None:
                out[key] = text
        return out

    # -- the parts ---------------------------------------------------------------
    def participant(self, node: Node, where: str) -> ParticipantMappingSection | None:
        example = "{channel: prediction, array: obstacles, fields: {id: id, x: x, y: y}}"
        if not self.mapping(node, MAPPING_KEYS, where, example) or not self.required(
                node, ("channel", "array", "fields"), where):
            return None
        v = node.value
        channel = self.channel(v["channel"], f"{where}.channel")
        array = self.path(v["array"], f"{where}.array")
        stamp = self.path(v["stamp"], f"{where}.stamp") if v.get("stamp") is not None else None
        fields = self.field_map(v["fields"], PARTICIPANT_ATTRIBUTES, f"{where}.fields")
        trajectory = self.trajectory(v["trajectory"], f"{where}.trajectory") if "trajectory" in v else None
        if channel is None or array is None or fields is None or ("trajectory" in v and trajectory is None):
            return None
        return ParticipantMappingSection(channel=channel, array=array, fields=fields, stamp=stamp,
                                         trajectory=trajectory)

    def trajectory(self, node: Node, where: str) -> TrajectorySection | None:
        if not self.mapping(node, TRAJECTORY_KEYS, where, "{array: trajectory, t: t, x: x, y: y}") \
                or not self.required(node, ("array", "t", "x", "y"), where):
            return None
        v = node.value
        array = self.path(v["array"], f"{where}.array")
        points = {k: self.path(v[k], f"{where}.{k}") for k in POINT_ATTRIBUTES if k in v}
        horizon = self.number(v["horizon"], f"{where}.horizon", 0.001, 3600.0, example="5.0") if "horizon" in v else 5.0
        step = self.number(v["step"], f"{where}.step", 0.001, 3600.0, example="0.1") if "step" in v else 0.1
        if array is None or horizon is None or step is None or any(p is None for p in points.values()):
            return None
        if step > horizon or horizon / step > MAX_TRAJECTORY_POINTS:
            self.src.at(node, f"{where}: step {step:g} s and horizon {horizon:g} s give "
                              f"{'no point' if step > horizon else f'{horizon / step:.0f} points'}",
                        f"0 < step <= horizon and at most {MAX_TRAJECTORY_POINTS} points, e.g. horizon: 5.0, step: 0.1")
            return None
        return TrajectorySection(array, {k: p for k, p in points.items() if p is not None}, horizon, step)

    def lanes(self, node: Node) -> LanesSection | None:
        where = "decictor.lanes"
        example = "{channel: routing, straight: {count: lane_count, width: lane_width, length: road_length}}"
        if not self.mapping(node, ("channel", "straight", "file"), where, example):
            return None
        v = node.value
        if "file" in v:
            name = self.text(v["file"], f"{where}.file")
            if name is None:
                return None
            return LanesSection(file=(self.base_dir / name).resolve())
        if "channel" not in v or "straight" not in v:
            self.src.at(node, f"{where}: needs 'file', or 'channel' with 'straight: {{count, width, length}}'",
                        f"e.g. lanes: {example}")
            return None
        channel = self.channel(v["channel"], f"{where}.channel")
        snode = v["straight"]
        if not self.mapping(snode, STRAIGHT_KEYS, f"{where}.straight", "{count: lane_count, width: lane_width, "
                                                                      "length: road_length}"):
            return None
        missing = [k for k in STRAIGHT_KEYS if k not in snode.value]
        if missing:
            self.src.at(snode, f"{where}.straight: missing '{missing[0]}'",
                        "name the fields holding the lane count, lane width and road length")
            return None
        straight = {k: self.path(snode.value[k], f"{where}.straight.{k}") for k in STRAIGHT_KEYS}
        if channel is None or any(p is None for p in straight.values()):
            return None
        return LanesSection(channel=channel, straight={k: str(p) for k, p in straight.items()})

    def ego(self, node: Node) -> EgoSection | None:
        where = "decictor.ego"
        if not self.mapping(node, ("channel", *EGO_FIELDS, *EGO_SIZES), where, "{channel: localization, x: x, y: y}") \
                or not self.required(node, ("channel",), where):
            return None
        v = node.value
        channel = self.channel(v["channel"], f"{where}.channel")
        names = {k: self.path(v[k], f"{where}.{k}") for k in EGO_FIELDS if k in v}
        sizes = {k: self.number(v[k], f"{where}.{k}", 0.01, 100.0, example="4.6") for k in EGO_SIZES if k in v}
        if channel is None or any(x is None for x in (*names.values(), *sizes.values())):
            return None
        given: dict[str, Any] = {**{k: str(p) for k, p in names.items()}, **sizes}
        return replace(EgoSection(channel=channel), **given)

    def flag(self, node: Node, key: str) -> FlagSection | None:
        where = f"decictor.{key}"
        if not self.mapping(node, FLAG_KEYS, where, f"{{channel: status, field: {key}}}") \
                or not self.required(node, FLAG_KEYS, where):
            return None
        channel = self.channel(node.value["channel"], f"{where}.channel")
        path = self.path(node.value["field"], f"{where}.field")
        return FlagSection(channel, path) if channel is not None and path is not None else None


def read_decictor_section(src: Source, node: Node | None, channels: tuple[str, ...],
                          base_dir: Path) -> DecictorSection | None:
    """The typed ``decictor:`` section (None without one); problems go to ``src`` with their lines."""
    if node is None:
        return None
    reader = _Reader(src, channels, base_dir)
    if not reader.mapping(node, SECTION_KEYS, "'decictor'", "decictor: {participants: [...], lanes: …}"):
        return None
    v = node.value
    participants: list[ParticipantMappingSection] = []
    if "participants" in v:
        pnode = v["participants"]
        if not pnode.is_list:
            src.at(pnode, "decictor.participants must be a list of channel mappings",
                   "write each as '- {channel: …, array: …, fields: {…}}'")
        else:
            for k, item in enumerate(pnode.value):
                mapping = reader.participant(item, f"decictor.participants[{k}]")
                if mapping is not None:
                    participants.append(mapping)
    clearance = (reader.number(v["clearance"], "decictor.clearance", 0.0, 100.0, example="1.5")
                 if "clearance" in v else None)
    dt = reader.number(v["dt"], "decictor.dt", 0.1, 60.0, example="2.0") if "dt" in v else None
    return DecictorSection(
        participants=tuple(participants),
        lanes=reader.lanes(v["lanes"]) if v.get("lanes") is not None else None,
        ego=reader.ego(v["ego"]) if v.get("ego") is not None else None,
        goal=reader.flag(v["goal"], "goal") if v.get("goal") is not None else None,
        collision=reader.flag(v["collision"], "collision") if v.get("collision") is not None else None,
        clearance=clearance, dt=dt)
