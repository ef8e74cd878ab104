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
        vx: vx                      # optional: velocity fields (m/s), to carry an obstacle past its last message

Ego and obstacles are compared at one instant: each message of either
channel is checked at its own time, with the other side interpolated
between the messages around that time (per obstacle id, heading the short
way round). The time is the one the channels declare (``pairing.Join``):
their own ``time:`` field, or the bus time of the first message of a
``pair_by:`` pair, so the ego and obstacles of one simulator tick meet
however far apart they were published; else the bus time, and a finding
whose overlap is within what interpolating across a message gap can move
a box says so and is not critical (the two channels' messages of one tick
may have been published apart). That waits for the other channel's next message, so online a
finding comes up to one message period late, but the one named is the same
offline. Where no later message comes (the end of a run, an obstacle that
appears or vanishes), the other side is carried by its velocity when
``vx``/``vy`` are declared, else held; the time it was carried or held over
is the residual skew, reported in each finding (``skew_s``) and as the
monitor's ``max_skew_s``. (Pairing a 20 Hz ego with the newest 10 Hz
obstacle message instead puts an obstacle at 5 m/s up to 0.5 m off.) Each obstacle's collision is reported once, when
it starts; it may be reported again after it has cleared. Values that are
not finite numbers are skipped here (a ``bound`` invariant reports those).
"""

from __future__ import annotations

import bisect
import collections
import dataclasses
import math
from dataclasses import dataclass
from typing import Any, ClassVar
from collections.abc import Callable

from astaa_deft.model.fields import FieldPath
from astaa_deft.model.sut import FieldType
from astaa_deft.io.yamlsource import Node
from astaa_deft.engine.monitor.base import NO_VIOLATIONS, EpisodeGate, Invariant, Monitor, MonitorContext
from astaa_deft.engine.monitor.expression import RUNTIME_ERRORS, follow
from astaa_deft.engine.monitor.paths import is_number
from astaa_deft.model.geometry import Box, box_between, box_moved, overlap
from astaa_deft.engine.monitor.pairing import Join, JoinMode
from astaa_deft.engine.monitor.spec_reader import InvariantReader
from astaa_deft.engine.monitor.violation import Violation, json_safe
from astaa_deft.engine.monitor.kinds import Kind

KEYS = ("ego", "obstacles", "margin")
REQUIRED = ("ego", "obstacles")
EGO_KEYS = ("channel", "x", "y", "heading", "length", "width", "offset")
OBSTACLE_KEYS = ("channel", "array", "id", "x", "y", "heading", "length", "width", "vx", "vy")
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
    obstacle_velocity: tuple[FieldPath, FieldPath] | None = None


def parse(reader: InvariantReader, node: Node, common: dict) -> CollisionInvariant | None:
    v = node.value
    margin = reader.number(v.get("margin"), "'margin'", minimum=0.0) if "margin" in v else 0.0
    ego = _ego(reader, v.get("ego"))
    obstacles = _obstacles(reader, v.get("obstacles"))
    if margin is None or ego is None or obstacles is None:
        return None
    ego_channel, ego_footprint = ego
    obstacle_channel, array, obstacle_id, footprint, velocity = obstacles
    return CollisionInvariant(ego_channel=ego_channel, ego=ego_footprint, obstacle_channel=obstacle_channel,
                              obstacle_array=array, obstacle_id=obstacle_id, obstacle=footprint, margin=margin,
                              obstacle_velocity=velocity, **common)


def _ego(reader: InvariantReader, node: Node | None) -> tuple[str, Footprint] | None:
    if node is None or not reader.keys(node, EGO_KEYS, ("channel", "length", "width"), "'ego'"):
        return None
    channel = reader.channel(node.value.get("channel"))
    if channel is None:
        return None
    footprint = _footprint(reader, node, channel.type, None, what="ego")
    if footprint is None:
        return None
    offset = reader.number(node.value.get("offset"), "'ego.offset'") if "offset" in node.value else 0.0
    if offset is None:
        return None
    return channel.name, Footprint(footprint.x, footprint.y, footprint.heading, footprint.length,
                                   footprint.width, offset)


def _obstacles(reader: InvariantReader, node: Node | None
               ) -> tuple[str, FieldPath, FieldPath | None, Footprint, tuple[FieldPath, FieldPath] | None] | None:
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
    velocity = None
    if "vx" in v or "vy" in v:
        if not ("vx" in v and "vy" in v):
            reader.problem(node, "'obstacles' declares one of 'vx', 'vy' but not the other", "declare both or neither")
            return None
        vx = reader.field(v["vx"], channel.type, "'obstacles.vx'", kinds=("number",), relative_to=element)
        vy = reader.field(v["vy"], channel.type, "'obstacles.vy'", kinds=("number",), relative_to=element)
        if vx is None or vy is None:
            return None
        velocity = (vx[0], vy[0])
    footprint = _footprint(reader, node, channel.type, element, what="obstacles")
    return (channel.name, array, obstacle_id, footprint, velocity) if footprint else None


def _footprint(reader: InvariantReader, node: Node, type_name: str, element: FieldType | None, *,
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


Obstacles = dict  # obstacle id → (box, element, (vx, vy) or None)


class _Track:
    """Time-stamped states of one side (ego or obstacles), oldest first, pruned as evaluation moves on."""

    def __init__(self) -> None:
        self.times: list[int] = []
        self.states: list[Any] = []

    def add(self, time_ns: int, state: Any) -> None:
        if not self.times or time_ns >= self.times[-1]:
            self.times.append(time_ns)
            self.states.append(state)
            return
        index = bisect.bisect_right(self.times, time_ns)  # a pair's late half: back in its place
        self.times.insert(index, time_ns)
        self.states.insert(index, state)

    def covers(self, time_ns: int) -> bool:
        return bool(self.times) and self.times[-1] >= time_ns

    def around(self, time_ns: int) -> tuple[tuple[int, Any] | None, tuple[int, Any] | None]:
        """The newest state at or before time_ns and the oldest at or after it."""
        index = bisect.bisect_left(self.times, time_ns)
        after = (self.times[index], self.states[index]) if index < len(self.times) else None
        if after is not None and after[0] == time_ns:
            return after, after
        before = (self.times[index - 1], self.states[index - 1]) if index > 0 else None
        return before, after

    def prune_before(self, time_ns: int) -> None:
        """Drop states no longer needed for times at or after time_ns (keep one before it)."""
        index = bisect.bisect_left(self.times, time_ns) - 1
        if index > 0:
            del self.times[:index]
            del self.states[:index]


class CollisionMonitor(Monitor):
    def __init__(self, invariant: CollisionInvariant, context: MonitorContext):
        super().__init__(invariant, context)
        self.inv = invariant
        self._ego_box = _BoxReader(invariant.ego)
        self._obstacle_box = _BoxReader(invariant.obstacle)
        self._array = invariant.obstacle_array.segments
        self._id = invariant.obstacle_id.segments if invariant.obstacle_id else None
        self._velocity = (None if invariant.obstacle_velocity is None
                          else tuple(p.segments for p in invariant.obstacle_velocity))
        self._join = Join(context.spec, {invariant.ego_channel, invariant.obstacle_channel})
        self._ego = _Track()
        self._obstacles = _Track()
        # instants to check: (joined time, bus time, channel, seq)
        self._pending: collections.deque[tuple[int, int, str, int]] = collections.deque()
        self._gate = EpisodeGate()
        self.max_skew_s = 0.0  # the longest a side was held or carried over at an evaluation

    def channels(self) -> set[str]:
        return {self.inv.ego_channel, self.inv.obstacle_channel}

    def on_message(self, channel: str, time_ns: int, value: dict | None, seq: int) -> list[Violation]:
        if value is None:
            return NO_VIOLATIONS
        at = self._join.at(channel, time_ns, value)
        if at is None:  # no time of its own where the channels join on theirs
            return self._evaluate_ready(final=False)
        # ego and obstacles may share a channel (one world-state message): update both first
        updated = False
        if channel == self.inv.ego_channel:
            box = self._ego_box(value)
            if box is not None:
                self._ego.add(at, box)
                updated = True
        if channel == self.inv.obstacle_channel:
            obstacles = self._read_obstacles(value)
            if obstacles is not None:
                self._obstacles.add(at, obstacles)
                updated = True
        if updated:
            self._pending.append((at, time_ns, channel, seq))
        return self._evaluate_ready(final=False)

    def finish(self, time_ns: int) -> list[Violation]:
        return self._evaluate_ready(final=True)

    def _evaluate_ready(self, final: bool) -> list[Violation]:
        """Evaluate pending instants both sides now cover (all of them at the end of the run)."""
        out: list[Violation] = []
        while self._pending:
            at, time_ns, channel, seq = self._pending[0]
            if not final and not (self._ego.covers(at) and self._obstacles.covers(at)):
                break
            self._pending.popleft()
            out.extend(self._check(channel, at, time_ns, seq))
        if self._pending:
            earliest = min(p[0] for p in self._pending)
            self._ego.prune_before(earliest)
            self._obstacles.prune_before(earliest)
        return out or NO_VIOLATIONS

    def _read_obstacles(self, message: dict) -> Obstacles | None:
        try:
            elements = follow(message, self._array)
        except RUNTIME_ERRORS:
            return None
        if type(elements) is not list:
            return None
        out: Obstacles = {}
        for index, element in enumerate(elements):
            box = self._obstacle_box(element)
            if box is None:
                continue
            out[self._identify(element, index)] = (box, element, self._read_velocity(element))
        return out

    def _read_velocity(self, element: Any) -> tuple[float, float] | None:
        if self._velocity is None:
            return None
        try:
            vx, vy = (follow(element, path) for path in self._velocity)
        except RUNTIME_ERRORS:
            return None
        if is_number(vx) and is_number(vy) and math.isfinite(vx) and math.isfinite(vy):
            return float(vx), float(vy)
        return None

    def _identify(self, element: Any, index: int) -> Any:
        if self._id is None:
            return index
        try:
            found = follow(element, self._id)
        except RUNTIME_ERRORS:
            return f"#{index}"
        return found if isinstance(found, (str, int, float, bool)) else f"#{index}"

    # -- alignment -------------------------------------------------------------
    def _ego_at(self, time_ns: int) -> tuple[Box, float, float] | None:
        """The ego's box at time_ns, the skew (s) it was held over and how far (m) it moved across the gap it
        was interpolated over; None before its first message."""
        before, after = self._ego.around(time_ns)
        if before is None:
            return None
        if after is None:
            return before[1], (time_ns - before[0]) * 1e-9, 0.0
        if after[0] == before[0]:
            return before[1], 0.0, 0.0
        fraction = (time_ns - before[0]) / (after[0] - before[0])
        return box_between(before[1], after[1], fraction), 0.0, _moved(before[1], after[1])

    def _obstacles_at(self, time_ns: int) -> list[tuple[Any, Box, Any, float, float]] | None:
        """(id, box, element, skew s, moved m across its interpolated gap) of each obstacle brought to time_ns;
        None before the first message."""
        before, after = self._obstacles.around(time_ns)
        if before is None:
            return None
        t0, older = before
        t1, newer = after if after is not None else (t0, {})  # no later message: nothing to bring back
        out = []
        for ident, (box, element, velocity) in older.items():
            if ident in newer:
                if t1 == t0:
                    out.append((ident, box, element, 0.0, 0.0))
                else:
                    box1 = newer[ident][0]
                    out.append((ident, box_between(box, box1, (time_ns - t0) / (t1 - t0)), element, 0.0,
                                _moved(box, box1)))
            else:  # no later state of this obstacle: carry it forward
                moved, skew = self._carried(box, velocity, (time_ns - t0) * 1e-9)
                out.append((ident, moved, element, skew, 0.0))
        for ident, (box, element, velocity) in newer.items():
            if ident not in older:  # it appears in the next message: bring it back
                moved, skew = self._carried(box, velocity, (time_ns - t1) * 1e-9)
                out.append((ident, moved, element, skew, 0.0))
        return out

    @staticmethod
    def _carried(box: Box, velocity: tuple[float, float] | None, dt: float) -> tuple[Box, float]:
        """The box moved dt seconds by its velocity (skew 0 then counts the dt), else held (skew |dt|)."""
        if velocity is not None:
            return box_moved(box, velocity[0], velocity[1], dt), abs(dt)
        return box, abs(dt)

    def _check(self, channel: str, at: int, time_ns: int, seq: int) -> list[Violation]:
        """The instant ``at`` (joined time) of the message of bus time ``time_ns`` (the findings' date)."""
        ego = self._ego_at(at)
        obstacles = self._obstacles_at(at)
        if ego is None or obstacles is None:
            return NO_VIOLATIONS
        self.evaluations += 1
        ego_box, ego_skew, ego_moved = ego
        grown = ego_box.grown(self.inv.margin)
        colliding = []
        out: list[Violation] = []
        by_bus = self._join.mode == JoinMode.BUS
        for obstacle_id, box, element, skew, moved in obstacles:
            skew = max(skew, ego_skew)
            self.max_skew_s = max(self.max_skew_s, skew)
            depth = overlap(grown, box)
            if depth <= 0.0:
                continue
            colliding.append(obstacle_id)
            if self._gate.broke(obstacle_id):
                uncertain = max(moved, ego_moved) if by_bus else 0.0
                out.append(self._violation(channel, time_ns, seq,
                                           _Overlap(obstacle_id, element, depth, ego_box, skew, uncertain)))
        if colliding:
            self.violating += 1
        self._gate.keep_only(colliding)
        return out

    def _violation(self, channel: str, time_ns: int, seq: int, found: _Overlap) -> Violation:
        margin = f" (with a {self.inv.margin:g} m margin)" if self.inv.margin else ""
        held = f"; a side held or carried over {found.skew:.3f} s" if found.skew else ""
        detail = f"ego footprint overlaps obstacle {found.obstacle_id!r} by {found.depth:.2f} m{margin}{held}"
        unsure = found.uncertain > 0.0 and found.depth <= found.uncertain
        if unsure:
            detail += (f"; within the {found.uncertain:.2f} m a box moved between the messages it was interpolated"
                       f" over by bus time — if one tick's messages are published apart, declare 'time:' or"
                       f" 'pair_by:' on channels '{self.inv.ego_channel}' and '{self.inv.obstacle_channel}'")
        ego = found.ego
        context = {"obstacle_id": json_safe(found.obstacle_id), "overlap_m": round(found.depth, 4),
                   "skew_s": round(found.skew, 6), "joined": str(self._join.mode),
                   "ego": {"x": ego.x, "y": ego.y, "heading": ego.heading, "length": ego.length,
                           "width": ego.width},
                   "obstacle": json_safe(found.element)}
        if found.uncertain > 0.0:
            context["interpolation_m"] = round(found.uncertain, 4)
        found_v = self.violation(time_ns, detail, channel=channel, seq=seq, message=context, infer_module=False)
        if unsure and found_v.severity == "critical":  # not critical while the join may have made it
            found_v = dataclasses.replace(found_v, severity="high")
        return found_v


@dataclass(frozen=True)
class _Overlap:
    """The ego footprint overlapping one obstacle at one time."""

    obstacle_id: Any
    element: Any  # the obstacle as its message gave it
    depth: float  # m
    ego: Box  # the ego footprint (without the margin)
    skew: float  # s: how far a side was held or carried over to this time
    uncertain: float = 0.0  # m: how far a side moved across the gap it was interpolated over (by bus time)


def _moved(before: Box, after: Box) -> float:
    """How far a box's centre moved between two states (m)."""
    return math.hypot(after.x - before.x, after.y - before.y)


def monitor(invariant: CollisionInvariant, context: MonitorContext) -> CollisionMonitor:
    return CollisionMonitor(invariant, context)


Kind.register(CollisionInvariant, KEYS, REQUIRED, parse=parse, monitor=monitor)
