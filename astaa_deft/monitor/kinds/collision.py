"""``collision``: the ego's footprint never overlaps an obstacle's (plus a margin).

    - name: no_collision
      kind: collision
      margin: 0.5                   # metres kept clear on every side of the ego (default 0)
      ego:
        channel: localization       # the ego pose: x, y, heading fields (the defaults shown)
        x: x
        y: y
        heading: heading            # a field, or a number (0: aligned with the x axis)
        length: 4.5                 # a number or a field
        width: 1.9
        offset: 1.4                 # footprint centre ahead of (x, y), e.g. when x, y is the rear axle
      obstacles:
        channel: obstacles          # ground truth or perception
        array: obstacles            # the array of obstacles in each message
        id: id                      # how a report names an obstacle (default: its index)
        x: x                        # each: a field of an element (defaults: these names), or a number
        y: y
        heading: heading
        length: length
        width: width

Each message of either channel is checked against the latest message of the
other (zero-order hold). Each obstacle's collision is reported once, when
it starts; it may be reported again after it has cleared. Values that are
not finite numbers are skipped here (a ``bound`` invariant reports those).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, ClassVar

from ...fields import FieldPath
from ...spec.model import FieldType
from ...yamlsource import Node
from ..base import NO_VIOLATIONS, EpisodeGate, Invariant, Monitor, MonitorContext
from ..expression import RUNTIME_ERRORS, follow
from ...geometry import Box, overlap
from ..spec_reader import InvariantReader
from ..violation import Violation, json_safe

KEYS = ("ego", "obstacles", "margin")
REQUIRED = ("ego", "obstacles")
EGO_KEYS = ("channel", "x", "y", "heading", "length", "width", "offset")
OBSTACLE_KEYS = ("channel", "array", "id", "x", "y", "heading", "length", "width")
DEFAULT_FIELDS = {"x": "x", "y": "y", "heading": "heading", "length": "length", "width": "width"}

@dataclass(frozen=True)
class Footprint:
    """Where to read a rectangle from a message (ego) or an array element (obstacles)."""

    x: FieldPath
    y: FieldPath
    heading: float | FieldPath
    length: float | FieldPath
    width: float | FieldPath
    offset: float = 0.0


@dataclass(frozen=True, kw_only=True)
class CollisionInvariant(Invariant):
    kind: ClassVar[str] = "collision"

    ego_channel: str
    ego: Footprint
    obstacle_channel: str
    obstacle_array: FieldPath
    obstacle_id: FieldPath | None
    obstacle: Footprint
    margin: float = 0.0


def parse(reader: InvariantReader, node: Node, common: dict) -> CollisionInvariant | None:
    v = node.value
    margin = reader.number(v.get("margin"), "'margin'", minimum=0.0) if "margin" in v else 0.0
    ego = _ego(reader, v.get("ego"))
    obstacles = _obstacles(reader, v.get("obstacles"))
    if margin is None or ego is None or obstacles is None:
        return None
    ego_channel, ego_footprint = ego
    obstacle_channel, array, obstacle_id, footprint = obstacles
    return CollisionInvariant(ego_channel=ego_channel, ego=ego_footprint, obstacle_channel=obstacle_channel,
                              obstacle_array=array, obstacle_id=obstacle_id, obstacle=footprint, margin=margin,
                              **common)


def _ego(reader: InvariantReader, node: Node | None) -> tuple[str, Footprint] | None:
    if node is None or not reader.keys(node, EGO_KEYS, ("channel", "length", "width"), "'ego'"):
        return None
    channel = reader.channel(node.value.get("channel"))
    if channel is None:
        return None
    footprint = _footprint(reader, node, channel.type, None, "ego")
    if footprint is None:
        return None
    offset = reader.number(node.value.get("offset"), "'ego.offset'") if "offset" in node.value else 0.0
    if offset is None:
        return None
    return channel.name, Footprint(footprint.x, footprint.y, footprint.heading, footprint.length,
                                   footprint.width, offset)


def _obstacles(reader: InvariantReader, node: Node | None
               ) -> tuple[str, FieldPath, FieldPath | None, Footprint] | None:
    if node is None or not reader.keys(node, OBSTACLE_KEYS, ("channel", "array"), "'obstacles'"):
        return None
    v = node.value
    channel = reader.channel(v.get("channel"))
    if channel is None:
        return None
    found = reader.field(v.get("array"), channel.type, "'obstacles.array'", kinds=("array",))
    if found is None:
        return None
    array, declared = found
    element = declared.items
    if element is None or element.kind != "struct" or not array.is_concrete:
        reader.problem(v["array"], "'obstacles.array' must name one array of objects (no [*])",
                       "e.g. array: obstacles")
        return None
    obstacle_id = None
    if "id" in v:
        found_id = reader.field(v["id"], channel.type, "'obstacles.id'", relative_to=element)
        if found_id is None:
            return None
        obstacle_id = found_id[0]
    footprint = _footprint(reader, node, channel.type, element, "obstacles")
    return (channel.name, array, obstacle_id, footprint) if footprint else None


def _footprint(reader: InvariantReader, node: Node, type_name: str, element: FieldType | None,
               what: str) -> Footprint | None:
    """x, y (fields), heading, length, width (fields or numbers), defaults filled in by name."""
    owner = element.ref if element is not None and element.ref else type_name
    values: dict[str, Any] = {}
    for key, default in DEFAULT_FIELDS.items():
        given = node.value.get(key)
        if given is None:
            if what == "ego" and key in ("length", "width"):
                return None  # required; keys() reported it
            fields = reader.types[owner].fields if owner in reader.types else {}
            if default not in fields:
                reader.problem(node, f"'{what}' lacks '{key}' and {owner} has no field '{default}'",
                               f"add '{key}: FIELD' (or a number{' for heading' if key == 'heading' else ''})")
                return None
            values[key] = FieldPath.parse(default)
            continue
        if key in ("x", "y"):
            found = reader.field(given, type_name, f"'{what}.{key}'", kinds=("number",), relative_to=element)
            values[key] = found[0] if found else None
        elif key == "heading" and isinstance(given.value, (int, float)) and not isinstance(given.value, bool):
            values[key] = reader.number(given, f"'{what}.heading'")  # a fixed angle: any sign, 0 included
        else:
            values[key] = reader.number_or_field(given, type_name, f"'{what}.{key}'", relative_to=element)
        if values[key] is None:
            return None
    return Footprint(values["x"], values["y"], values["heading"], values["length"], values["width"])


def _reader(quantity: float | FieldPath) -> Callable[[Any], Any]:
    if isinstance(quantity, FieldPath):
        segments = quantity.segments
        return lambda value: follow(value, segments)
    return lambda value: quantity


class _BoxReader:
    """Reads a Box from a message or element; None when a value is missing or not a finite number."""

    def __init__(self, footprint: Footprint):
        self._parts = tuple(_reader(q) for q in (footprint.x, footprint.y, footprint.heading,
                                                 footprint.length, footprint.width))
        self._offset = footprint.offset

    def __call__(self, value: Any) -> Box | None:
        try:
            numbers = [read(value) for read in self._parts]
        except RUNTIME_ERRORS:
            return None
        for number in numbers:
            if type(number) not in (int, float) or not math.isfinite(number):
                return None
        x, y, heading, length, width = numbers
        if self._offset:
            x += self._offset * math.cos(heading)
            y += self._offset * math.sin(heading)
        return Box(x, y, heading, length, width)


class CollisionMonitor(Monitor):
    def __init__(self, invariant: CollisionInvariant, context: MonitorContext):
        super().__init__(invariant, context)
        self.inv = invariant
        self._ego_box = _BoxReader(invariant.ego)
        self._obstacle_box = _BoxReader(invariant.obstacle)
        self._array = invariant.obstacle_array.segments
        self._id = invariant.obstacle_id.segments if invariant.obstacle_id else None
        self._ego: tuple[Box, dict] | None = None
        self._obstacles: list[tuple[Any, Box, dict]] | None = None
        self._gate = EpisodeGate()

    def channels(self) -> set[str]:
        return {self.inv.ego_channel, self.inv.obstacle_channel}

    def on_message(self, channel: str, time_ns: int, value: dict | None, seq: int) -> list[Violation]:
        if value is None:
            return NO_VIOLATIONS
        # ego and obstacles may share a channel (one world-state message): update both first
        if channel == self.inv.ego_channel:
            box = self._ego_box(value)
            if box is not None:
                self._ego = (box, value)
        if channel == self.inv.obstacle_channel:
            self._obstacles = self._read_obstacles(value)
        if self._ego is None or self._obstacles is None:
            return NO_VIOLATIONS
        return self._check(channel, time_ns, seq)

    def _read_obstacles(self, message: dict) -> list[tuple[Any, Box, dict]] | None:
        try:
            elements = follow(message, self._array)
        except RUNTIME_ERRORS:
            return None
        if type(elements) is not list:
            return None
        out = []
        for index, element in enumerate(elements):
            box = self._obstacle_box(element)
            if box is None:
                continue
            out.append((self._identify(element, index), box, element))
        return out

    def _identify(self, element: Any, index: int) -> Any:
        if self._id is None:
            return index
        try:
            found = follow(element, self._id)
        except RUNTIME_ERRORS:
            return f"#{index}"
        return found if isinstance(found, (str, int, float, bool)) else f"#{index}"

    def _check(self, channel: str, time_ns: int, seq: int) -> list[Violation]:
        assert self._ego is not None and self._obstacles is not None
        self.evaluations += 1
        ego_box, _ = self._ego
        grown = ego_box.grown(self.inv.margin)
        colliding = []
        out: list[Violation] = []
        for obstacle_id, box, element in self._obstacles:
            depth = overlap(grown, box)
            if depth <= 0.0:
                continue
            colliding.append(obstacle_id)
            if self._gate.broke(obstacle_id):
                out.append(self._violation(channel, time_ns, seq, obstacle_id, depth, ego_box, element))
        if colliding:
            self.violating += 1
        self._gate.keep_only(colliding)
        return out

    def _violation(self, channel: str, time_ns: int, seq: int, obstacle_id: Any, depth: float, ego: Box,
                   element: Any) -> Violation:
        margin = f" (with a {self.inv.margin:g} m margin)" if self.inv.margin else ""
        detail = f"ego footprint overlaps obstacle {obstacle_id!r} by {depth:.2f} m{margin}"
        context = {"obstacle_id": json_safe(obstacle_id), "overlap_m": round(depth, 4),
                   "ego": {"x": ego.x, "y": ego.y, "heading": ego.heading, "length": ego.length,
                           "width": ego.width},
                   "obstacle": json_safe(element)}
        return self.violation(time_ns, detail, channel=channel, seq=seq, message=context, infer_module=False)


def monitor(invariant: CollisionInvariant, context: MonitorContext) -> CollisionMonitor:
    return CollisionMonitor(invariant, context)
