"""``participant``: add a traffic participant to every selected message of a channel.

    <participant id="901" kind="cone" x="60" y="-2.9" heading="0" length="0.5" width="0.5"/>
    <participant id="902" kind="vehicle" x="30" y="3.5" length="4.6" width="1.9" t="0">
      <at t="4" x="70" y="3.5"/>
      <at t="8" x="100" y="3.5"/>
    </participant>

The participant is appended to an array field of the message (the demo's
``obstacles``), rendered at the message's own time: static at its pose, or
moving along a timed path (at its pose until ``t``, then straight between
the ``at`` waypoints, held at the last one). Where the element carries a
predicted trajectory it is filled in from the participant's true motion.
Decictor (``astaa_deft.analysis.decictor``) uses it to inject harmless participants
the planner has to ignore; it is a plain ASTAA action too.

How a participant maps onto a channel's fields is the spec's ``decictor:``
section, ``participants:`` (docs/decictor.md)::

    decictor:
      participants:
        - channel: prediction
          array: obstacles
          stamp: header.stamp           # the message's time (the path's clock); else seconds since run start
          fields: {id: id, kind: kind, length: length, width: width}
          trajectory: {array: trajectory, t: t, x: x, y: y, heading: heading, horizon: 5.0, step: 0.1}

``fields`` maps participant attributes (id, kind, x, y, heading, vx, vy,
speed, length, width) to the element's fields.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

from astaa_deft.io.codecs import DecodeError
from astaa_deft.model.errors import AstaaDeftError, InputError, Problem
from astaa_deft.model.fields import FieldPath, FieldPathError, FieldType, get, type_at
from astaa_deft.model.json import JsonObject, JsonValue
from astaa_deft.engine.intercept.actions.base import (
    ACTIONS, ActionConfig, ActionDetail, ActionRuntime, MessageInfo, Pending, PinnedStep, PolicyContext,
    decimal_text, required,
)

if TYPE_CHECKING:
    from lxml import etree

    from astaa_deft.model.decictor import ParticipantMappingSection
    from astaa_deft.model.sut import Channel, Spec
    from astaa_deft.engine.intercept.testcase import ActionChecker, Policy

MAPPING_DOCS = "docs/decictor.md"


# ---------------------------------------------------------------- the participant and its motion

@dataclass(frozen=True)
class Waypoint:
    t: float
    x: float
    y: float


@dataclass(frozen=True, kw_only=True)
class ParticipantPose:
    x: float
    y: float
    heading: float
    vx: float
    vy: float

    @property
    def speed(self) -> float:
        return math.hypot(self.vx, self.vy)


@dataclass(frozen=True, kw_only=True)
class ParticipantDetail(ActionDetail):
    shown: ClassVar[tuple[str, ...]] = ("participant", "x", "y")
    participant: int | None = None
    x: float | None = None  # where it was rendered
    y: float | None = None
    at: float | None = None  # the message time it was rendered for
    skipped: str | None = None


@ACTIONS.register_class
@dataclass(frozen=True, kw_only=True)
class Participant(ActionConfig):
    """A participant: id, kind, pose (x, y, heading), size, and a motion (static, or a timed path).

    ``t`` is the time it is at its pose (on the channel's clock: any finite
    time, seconds since the start or epoch seconds of a wall-clock stack);
    ``path`` the later waypoints, times increasing. No path: static.
    """

    name: ClassVar[str] = "participant"
    # Append a traffic participant to an array field of every selected message (docs/decictor.md):
    # pose x, y, heading at time t (on the channel's clock), size, and a motion: static, or straight
    # lines through the <at> waypoints.
    schema: ClassVar[str] = """
      <xs:complexType>
        <xs:sequence>
          <xs:element name="at" minOccurs="0" maxOccurs="1000">
            <xs:complexType>
              <xs:attribute name="t" type="Time" use="required"/>
              <xs:attribute name="x" type="Coordinate" use="required"/>
              <xs:attribute name="y" type="Coordinate" use="required"/>
            </xs:complexType>
          </xs:element>
        </xs:sequence>
        <xs:attribute name="id" type="ParticipantId" use="required"/>
        <xs:attribute name="kind" type="Name" default="vehicle"/>
        <xs:attribute name="x" type="Coordinate" use="required"/>
        <xs:attribute name="y" type="Coordinate" use="required"/>
        <xs:attribute name="heading" type="Coordinate" default="0"/>
        <xs:attribute name="length" type="Size" default="4.6"/>
        <xs:attribute name="width" type="Size" default="1.9"/>
        <xs:attribute name="t" type="Time" default="0"/>
      </xs:complexType>"""
    detail_type: ClassVar[type[ActionDetail]] = ParticipantDetail
    id: int
    kind: str
    x: float
    y: float
    heading: float = 0.0
    length: float = 4.6
    width: float = 1.9
    t: float = 0.0
    path: tuple[Waypoint, ...] = ()

    @property
    def static(self) -> bool:
        return not self.path

    def waypoints(self) -> tuple[Waypoint, ...]:
        return (Waypoint(self.t, self.x, self.y), *self.path)

    def pose_at(self, t: float) -> ParticipantPose:
        """Where it is at ``t``: held before its start and after its last waypoint, straight lines between."""
        points = self.waypoints()
        if self.static or t <= points[0].t:
            return ParticipantPose(x=self.x, y=self.y, heading=self._heading_leaving(0), vx=0.0, vy=0.0)
        for a, b in zip(points, points[1:], strict=False):
            if t < b.t:
                u = (t - a.t) / (b.t - a.t)
                dt = b.t - a.t
                vx, vy = (b.x - a.x) / dt, (b.y - a.y) / dt
                heading = math.atan2(vy, vx) if (vx or vy) else self.heading
                return ParticipantPose(x=a.x + u * (b.x - a.x), y=a.y + u * (b.y - a.y), heading=heading, vx=vx, vy=vy)
        last = points[-1]
        return ParticipantPose(x=last.x, y=last.y, heading=self._heading_leaving(len(points) - 2), vx=0.0, vy=0.0)

    def _heading_leaving(self, index: int) -> float:
        points = self.waypoints()
        if self.static or index < 0 or index + 1 >= len(points):
            return self.heading
        a, b = points[index], points[index + 1]
        return math.atan2(b.y - a.y, b.x - a.x) if (b.x != a.x or b.y != a.y) else self.heading

    # -- XML ------------------------------------------------------------
    @classmethod
    def from_xml(cls, element: etree._Element, checker: ActionChecker) -> Participant:
        for node in (element, *element.iterfind("at")):  # a decimal of 400 digits is a float infinity: refused
            for attr in ("t", "x", "y", "heading", "length", "width"):
                text = node.get(attr)
                if text is not None and not math.isfinite(float(text)):
                    checker.report(node, f"{attr}={text[:40]}{'…' if len(text) > 40 else ''} is not a finite number",
                                   f"give {attr} as a finite decimal (its magnitude below 1e308)", attribute=attr)
        path = tuple(Waypoint(float(required(at, "t")), float(required(at, "x")), float(required(at, "y")))
                     for at in element.iterfind("at"))
        start = float(element.get("t", "0"))
        times = [start] + [w.t for w in path]
        for k, (before, after) in enumerate(zip(times, times[1:], strict=False)):
            if after <= before:
                checker.report(list(element.iterfind("at"))[k],
                               f"waypoint times must increase: t={decimal_text(after)} after t={decimal_text(before)}",
                               "give each <at> a later t than the one before (and than the participant's t)",
                               attribute="t")
        return cls(id=int(required(element, "id")), kind=element.get("kind", "vehicle"),
                   x=float(required(element, "x")), y=float(required(element, "y")),
                   heading=float(element.get("heading", "0")), length=float(element.get("length", "4.6")),
                   width=float(element.get("width", "1.9")), t=start, path=path)

    def write_xml(self, element: etree._Element) -> None:
        from lxml import etree as _etree

        element.set("id", str(self.id))
        element.set("kind", self.kind)
        for attr in ("x", "y", "heading", "length", "width", "t"):
            element.set(attr, decimal_text(getattr(self, attr)))
        for w in self.path:
            _etree.SubElement(element, "at", t=decimal_text(w.t), x=decimal_text(w.x), y=decimal_text(w.y))

    def check(self, policy: Policy, channels: tuple[Channel, ...], checker: ActionChecker) -> None:
        if checker.spec is None:
            return
        try:
            mappings = read_mappings(checker.spec)
        except MappingError as exc:
            checker.report(None, str(exc), exc.fix)
            return
        for channel in channels:
            if channel.name not in mappings:
                checker.report(None, f"channel '{channel.name}' has no participant mapping in the spec",
                               "add it under decictor: participants: in the spec (see docs/decictor.md), or use "
                               + (", ".join(sorted(mappings)) or "another channel"))

    @classmethod
    def pinned(cls, step: PinnedStep) -> Participant | None:
        """The participant as written: what it adds to a message depends on the message's time alone."""
        return step.original if isinstance(step.original, cls) else None

    def start(self, context: PolicyContext) -> ActionRuntime:
        try:
            mappings = read_mappings(context.spec)
        except MappingError as exc:
            raise InputError(Problem(context.where, context.policy.line, None,
                                     f"policy '{context.policy.id}': {exc}", exc.fix)) from None
        missing = [c.name for c in context.channels if c.name not in mappings]
        if missing:
            raise InputError(Problem(context.where, context.policy.line, None,
                                     f"policy '{context.policy.id}': channel '{missing[0]}' has no participant "
                                     "mapping in the spec", "add it under decictor: participants: (docs/decictor.md)"))
        return ParticipantRuntime(self, context, mappings)


# ---------------------------------------------------------------- the spec's mapping

class MappingError(AstaaDeftError, ValueError):

    exit_code = 2  # bad input: the CLI prints it as one line
    def __init__(self, message: str, fix: str = f"see {MAPPING_DOCS}"):
        super().__init__(message)
        self.fix = fix


@dataclass(frozen=True)
class TrajectoryMapping:
    array: str
    fields: dict[str, str]  # point attribute (t, x, y, heading) → field
    horizon: float
    step: float


@dataclass(frozen=True, kw_only=True)
class ChannelMapping:
    channel: str
    array: FieldPath
    stamp: FieldPath | None
    fields: dict[str, str]  # participant attribute → element field
    trajectory: TrajectoryMapping | None = None


def read_mappings(spec: Spec) -> dict[str, ChannelMapping]:
    """The spec's ``decictor.participants`` (shape checked by the loader), checked against the channels' types."""
    section = spec.decictor
    if section is None or not section.participants:
        raise MappingError("the spec has no 'decictor: participants:' section saying how a participant maps onto "
                           "a channel's fields", f"add one (example in {MAPPING_DOCS})")
    out: dict[str, ChannelMapping] = {}
    for k, item in enumerate(section.participants):
        mapping = _read_mapping(spec, item, f"decictor.participants[{k}]")
        out[mapping.channel] = mapping
    return out


def _read_mapping(spec: Spec, item: ParticipantMappingSection, where: str) -> ChannelMapping:
    channel = spec.channel(item.channel)
    array = _path(item.array, f"{where}.array")
    element = _field_type(spec, channel.type, FieldPath.parse(f"{array}[*]"), f"{where}.array")
    if element.kind != "struct":
        raise MappingError(f"{where}.array: '{array}' of channel '{item.channel}' is not an array of structures")
    stamp = _path(item.stamp, f"{where}.stamp") if item.stamp else None
    if stamp is not None:
        _field_type(spec, channel.type, stamp, f"{where}.stamp")
    fields = dict(item.fields)
    for attr, field_name in fields.items():
        _field_type(spec, channel.type, FieldPath.parse(f"{array}[*].{field_name}"), f"{where}.fields.{attr}")
    trajectory = None
    if item.trajectory is not None:
        t = item.trajectory
        point_fields = dict(t.points)
        for attr, field_name in point_fields.items():
            _field_type(spec, channel.type, FieldPath.parse(f"{array}[*].{t.array}[*].{field_name}"),
                        f"{where}.trajectory.{attr}")
        trajectory = TrajectoryMapping(t.array, point_fields, t.horizon, t.step)
    return ChannelMapping(channel=item.channel, array=array, stamp=stamp, fields=fields, trajectory=trajectory)


def _path(text: Any, where: str) -> FieldPath:
    try:
        return FieldPath.parse(str(text))
    except FieldPathError as exc:
        raise MappingError(f"{where}: invalid field path {text!r}: {exc.reason}") from None


def _field_type(spec: Spec, type_name: str, path: FieldPath, where: str) -> FieldType:
    try:
        return type_at(spec.types, type_name, path)
    except FieldPathError as exc:
        raise MappingError(f"{where}: {type_name} has no field '{path}': {exc.reason}",
                           "map onto fields the channel's type declares") from None


# ---------------------------------------------------------------- rendering

def render(participant: Participant, mapping: ChannelMapping, t: float) -> JsonObject:
    """The array element for ``participant`` in a message of time ``t``."""
    pose = participant.pose_at(t)
    values: dict[str, JsonValue] = {
        "id": participant.id, "kind": participant.kind, "x": pose.x, "y": pose.y, "heading": pose.heading,
        "vx": pose.vx, "vy": pose.vy, "speed": pose.speed, "length": participant.length, "width": participant.width}
    element: JsonObject = {field_name: values[attr] for attr, field_name in mapping.fields.items()}
    if mapping.trajectory is not None:
        tm = mapping.trajectory
        points: list[JsonValue] = []
        for k in range(int(round(tm.horizon / tm.step)) + 1):
            at = round(t + k * tm.step, 9)
            p = participant.pose_at(at)
            point = {"t": at, "x": p.x, "y": p.y, "heading": p.heading}
            points.append({field_name: point[attr] for attr, field_name in tm.fields.items()})
        element[tm.array] = points
    return element


class ParticipantRuntime(ActionRuntime):
    def __init__(self, config: Participant, context: PolicyContext, mappings: dict[str, ChannelMapping]):
        self.config = config
        self.context = context
        self.mappings = mappings

    def apply(self, item: Pending, info: MessageInfo) -> list[Pending]:
        if item.message is None:
            try:
                item.message = info.codec.decode(item.payload)  # type: ignore[arg-type]
            except DecodeError as exc:
                return self._skip(item, info, f"undecodable: {exc}")
        mapping = self.mappings[info.channel]
        t = info.now
        if mapping.stamp is not None:
            found = get(item.message, mapping.stamp)
            stamp = found[0][1] if found else None
            if not isinstance(stamp, (int, float)) or isinstance(stamp, bool) or not math.isfinite(stamp):
                return self._skip(item, info, f"no usable time at {mapping.stamp}")
            t = float(stamp)
        arrays = get(item.message, mapping.array)
        if not arrays or not isinstance(arrays[0][1], list):
            return self._skip(item, info, f"no array at {mapping.array}")
        array = arrays[0][1]
        element = render(self.config, mapping, t)
        array.append(element)
        pose = self.config.pose_at(t)
        detail = ParticipantDetail(participant=self.config.id, x=round(pose.x, 3), y=round(pose.y, 3), at=t)
        item.events.append(self.context.event("participant", info, item.consumers, detail=detail.to_json()))
        return [item]

    def _skip(self, item: Pending, info: MessageInfo, why: str) -> list[Pending]:
        item.events.append(self.context.event("participant", info, item.consumers,
            detail=ParticipantDetail(participant=self.config.id, skipped=why).to_json()))
        return [item]
