"""Typed readers for the demo stack's JSON messages.

Each module reads the messages it consumes through these functions, the way
a middleware deserialiser would: a message with a missing field or a field
of the wrong JSON type raises ``BadMessage`` and is dropped by the caller.
Values are *not* judged here — NaN, infinities, negative speeds and empty
lists pass through, because deciding what a value means is each module's job
(and where the seeded defects live).

Field names here must match ``astaa_deft/data/specs/demo_av.yaml``.
"""

from __future__ import annotations

from typing import Any, NamedTuple
from collections.abc import Mapping


class BadMessage(ValueError):
    """A payload that does not have the shape of the expected message."""


def _get(msg: Mapping[str, Any], key: str) -> Any:
    if not isinstance(msg, Mapping):
        raise BadMessage(f"expected an object holding {key!r}, got {type(msg).__name__}")
    try:
        return msg[key]
    except KeyError:
        raise BadMessage(f"missing field {key!r}") from None


def num(msg: Mapping[str, Any], key: str) -> float:
    value = _get(msg, key)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise BadMessage(f"field {key!r}: expected a number, got {value!r}")
    return float(value)


def integer(msg: Mapping[str, Any], key: str) -> int:
    value = _get(msg, key)
    if isinstance(value, bool) or not isinstance(value, int):
        raise BadMessage(f"field {key!r}: expected an integer, got {value!r}")
    return value


def text(msg: Mapping[str, Any], key: str) -> str:
    value = _get(msg, key)
    if not isinstance(value, str):
        raise BadMessage(f"field {key!r}: expected a string, got {value!r}")
    return value


def items(msg: Mapping[str, Any], key: str) -> list:
    value = _get(msg, key)
    if not isinstance(value, list):
        raise BadMessage(f"field {key!r}: expected a list, got {type(value).__name__}")
    return value


class Header(NamedTuple):
    seq: int
    stamp: float


def header(msg: Mapping[str, Any]) -> Header:
    h = _get(msg, "header")
    return Header(seq=integer(h, "seq"), stamp=num(h, "stamp"))


class Localization(NamedTuple):
    stamp: float
    x: float
    y: float
    heading: float
    speed: float
    acceleration: float
    yaw_rate: float


def localization(msg: Mapping[str, Any]) -> Localization:
    return Localization(
        stamp=header(msg).stamp,
        x=num(msg, "x"),
        y=num(msg, "y"),
        heading=num(msg, "heading"),
        speed=num(msg, "speed"),
        acceleration=num(msg, "acceleration"),
        yaw_rate=num(msg, "yaw_rate"),
    )


class PerceivedObstacle(NamedTuple):
    id: int
    kind: str
    x: float
    y: float
    heading: float
    vx: float
    vy: float
    length: float
    width: float


def perception(msg: Mapping[str, Any]) -> tuple[float, list[PerceivedObstacle]]:
    """(stamp, obstacles) of a ``demo/sim/obstacles`` message."""
    return header(msg).stamp, [
        PerceivedObstacle(
            id=integer(o, "id"), kind=text(o, "kind"), x=num(o, "x"), y=num(o, "y"),
            heading=num(o, "heading"), vx=num(o, "vx"), vy=num(o, "vy"),
            length=num(o, "length"), width=num(o, "width"),
        )
        for o in items(msg, "obstacles")
    ]


class PredictedPose(NamedTuple):
    t: float
    x: float
    y: float
    heading: float


class PredictedObstacle(NamedTuple):
    id: int
    kind: str
    length: float
    width: float
    trajectory: list[PredictedPose]


def prediction(msg: Mapping[str, Any]) -> tuple[float, list[PredictedObstacle]]:
    """(stamp, obstacles) of a ``demo/prediction/obstacles`` message."""
    return header(msg).stamp, [
        PredictedObstacle(
            id=integer(o, "id"), kind=text(o, "kind"),
            length=num(o, "length"), width=num(o, "width"),
            trajectory=[
                PredictedPose(t=num(p, "t"), x=num(p, "x"), y=num(p, "y"), heading=num(p, "heading"))
                for p in items(o, "trajectory")
            ],
        )
        for o in items(msg, "obstacles")
    ]


class Routing(NamedTuple):
    lane_count: int
    lane_width: float
    road_length: float
    goal_x: float
    goal_lane: int
    speed_limit: float


def routing(msg: Mapping[str, Any]) -> Routing:
    goal = _get(msg, "goal")
    return Routing(
        lane_count=integer(msg, "lane_count"),
        lane_width=num(msg, "lane_width"),
        road_length=num(msg, "road_length"),
        goal_x=num(goal, "x"),
        goal_lane=integer(goal, "lane"),
        speed_limit=num(msg, "speed_limit"),
    )


class TrafficLight(NamedTuple):
    id: int
    state: str
    stop_line_x: float


def traffic_lights(msg: Mapping[str, Any]) -> list[TrafficLight]:
    return [
        TrafficLight(id=integer(light, "id"), state=text(light, "state"), stop_line_x=num(light, "stop_line_x"))
        for light in items(msg, "lights")
    ]


class TrajectoryPoint(NamedTuple):
    t: float
    x: float
    y: float
    heading: float
    v: float
    a: float


def trajectory(msg: Mapping[str, Any]) -> list[TrajectoryPoint]:
    return [
        TrajectoryPoint(t=num(p, "t"), x=num(p, "x"), y=num(p, "y"),
                        heading=num(p, "heading"), v=num(p, "v"), a=num(p, "a"))
        for p in items(msg, "points")
    ]


class Command(NamedTuple):
    steering: float
    acceleration: float


def command(msg: Mapping[str, Any]) -> Command:
    return Command(steering=num(msg, "steering"), acceleration=num(msg, "acceleration"))
