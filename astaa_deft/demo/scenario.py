"""Scenario files (``demo/scenarios/*.yaml``): what the simulated world contains.

A scenario is pure data. ``load_scenario`` accepts a bundled scenario's name
(``cut_in``) or a path to a YAML file, checks every key and value, and says
which one is wrong instead of failing later inside the simulator.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any
from collections.abc import Callable, Mapping

import yaml

SCENARIO_DIR = Path(__file__).resolve().parent / "scenarios"
LIGHT_STATES = ("red", "yellow", "green")
OBSTACLE_KINDS = ("vehicle", "truck", "barrier", "cone", "pedestrian")


class ScenarioError(ValueError):
    pass


@dataclass(frozen=True)
class Road:
    lanes: int
    lane_width: float
    length: float

    def lane_center(self, lane: int) -> float:
        # Lane 0 is the rightmost lane, centred on y = 0; lanes grow to the left (+y).
        return lane * self.lane_width


@dataclass(frozen=True)
class Trigger:
    """When a scripted maneuver starts: every condition given must hold."""

    time: float | None = None  # sim time reached
    ego_x: float | None = None  # ego centre has reached this x
    gap: float | None = None  # the NPC is ahead of the ego by at most this much (centre x distance)


@dataclass(frozen=True, kw_only=True)
class Maneuver:
    when: Trigger
    lane_change: int | None = None  # target lane
    duration: float = 3.0  # of a lane change, seconds
    speed: float | None = None  # target speed
    accel: float = 2.0  # magnitude used to reach it, m/s²


@dataclass(frozen=True, kw_only=True)
class ObjectSpec:
    """A static obstacle or an NPC vehicle at its initial state."""

    name: str
    kind: str
    lane: int
    x: float
    offset: float = 0.0  # lateral offset from the lane centre, metres (+ = left)
    heading: float = 0.0
    speed: float = 0.0
    length: float = 4.6
    width: float = 1.9
    maneuvers: tuple[Maneuver, ...] = ()


@dataclass(frozen=True)
class TrafficLightSpec:
    id: int
    stop_line_x: float
    cycle: tuple[tuple[str, float], ...]  # (state, seconds), repeated from sim time 0

    def state_at(self, t: float) -> str:
        period = sum(d for _, d in self.cycle)
        phase = t % period
        for state, duration in self.cycle:
            if phase < duration:
                return state
            phase -= duration
        return self.cycle[-1][0]


@dataclass(frozen=True, kw_only=True)
class Scenario:
    name: str
    description: str
    road: Road
    speed_limit: float
    time_limit: float
    ego_lane: int
    ego_x: float
    ego_speed: float
    goal_x: float
    goal_lane: int
    obstacles: tuple[ObjectSpec, ...] = ()
    npcs: tuple[ObjectSpec, ...] = ()
    traffic_lights: tuple[TrafficLightSpec, ...] = ()
    source: str = ""


def scenario_path(name_or_path: str) -> Path:
    """A bundled scenario's file, or the given path if it names a file."""
    candidate = Path(name_or_path)
    if candidate.suffix in (".yaml", ".yml") or candidate.exists():
        return candidate
    return SCENARIO_DIR / f"{name_or_path}.yaml"


def bundled_scenarios() -> list[str]:
    return sorted(p.stem for p in SCENARIO_DIR.glob("*.yaml"))


def load_scenario(name_or_path: str) -> Scenario:
    path = scenario_path(name_or_path)
    if not path.is_file():
        raise ScenarioError(
            f"no scenario {name_or_path!r}: not a file and not one of {', '.join(bundled_scenarios())}"
        )
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        raise ScenarioError(f"{path}: not valid YAML: {exc}") from exc
    return parse_scenario(data, source=str(path))


def parse_scenario(data: Any, source: str = "<scenario>") -> Scenario:
    r = _Reader(source)
    top = r.mapping(data, "scenario", required=("name", "road", "speed_limit", "ego", "goal"),
                    optional=("description", "time_limit", "obstacles", "npcs", "traffic_lights"))
    road_map = r.mapping(top["road"], "road", required=("lanes", "lane_width", "length"))
    road = Road(
        lanes=r.integer(road_map["lanes"], "road.lanes", minimum=1),
        lane_width=r.number(road_map["lane_width"], "road.lane_width", minimum=2.0),
        length=r.number(road_map["length"], "road.length", minimum=10.0),
    )
    ego = r.mapping(top["ego"], "ego", required=("lane", "x"), optional=("speed",))
    goal = r.mapping(top["goal"], "goal", required=("x",), optional=("lane",))

    def lane(value: Any, where: str) -> int:
        return r.integer(value, where, minimum=0, maximum=road.lanes - 1)

    return Scenario(
        name=r.string(top["name"], "name"),
        description=r.string(top.get("description", ""), "description"),
        road=road,
        speed_limit=r.number(top["speed_limit"], "speed_limit", minimum=1.0),
        time_limit=r.number(top.get("time_limit", 30.0), "time_limit", minimum=1.0),
        ego_lane=lane(ego["lane"], "ego.lane"),
        ego_x=r.number(ego["x"], "ego.x", minimum=0.0, maximum=road.length),
        ego_speed=r.number(ego.get("speed", 0.0), "ego.speed", minimum=0.0),
        goal_x=r.number(goal["x"], "goal.x", minimum=0.0, maximum=road.length),
        goal_lane=lane(goal.get("lane", ego["lane"]), "goal.lane"),
        obstacles=tuple(
            _object(r, item, f"obstacles[{i}]", lane, moving=False)
            for i, item in enumerate(r.sequence(top.get("obstacles", []), "obstacles"))
        ),
        npcs=tuple(
            _object(r, item, f"npcs[{i}]", lane, moving=True)
            for i, item in enumerate(r.sequence(top.get("npcs", []), "npcs"))
        ),
        traffic_lights=tuple(
            _light(r, item, f"traffic_lights[{i}]")
            for i, item in enumerate(r.sequence(top.get("traffic_lights", []), "traffic_lights"))
        ),
        source=source,
    )


def _object(r: _Reader, data: Any, where: str, lane: Callable[[Any, str], int], moving: bool) -> ObjectSpec:
    optional = ("offset", "heading", "length", "width") + (("speed", "maneuvers") if moving else ())
    m = r.mapping(data, where, required=("name", "kind", "lane", "x"), optional=optional)
    kind = r.string(m["kind"], f"{where}.kind")
    if kind not in OBSTACLE_KINDS:
        raise ScenarioError(f"{r.source}: {where}.kind: {kind!r} is not one of {', '.join(OBSTACLE_KINDS)}")
    return ObjectSpec(
        name=r.string(m["name"], f"{where}.name"),
        kind=kind,
        lane=lane(m["lane"], f"{where}.lane"),
        x=r.number(m["x"], f"{where}.x"),
        offset=r.number(m.get("offset", 0.0), f"{where}.offset"),
        heading=r.number(m.get("heading", 0.0), f"{where}.heading"),
        speed=r.number(m.get("speed", 0.0), f"{where}.speed", minimum=0.0),
        length=r.number(m.get("length", 4.6), f"{where}.length", minimum=0.1),
        width=r.number(m.get("width", 1.9), f"{where}.width", minimum=0.1),
        maneuvers=tuple(
            _maneuver(r, item, f"{where}.maneuvers[{i}]", lane)
            for i, item in enumerate(r.sequence(m.get("maneuvers", []), f"{where}.maneuvers"))
        ),
    )


def _maneuver(r: _Reader, data: Any, where: str, lane: Callable[[Any, str], int]) -> Maneuver:
    m = r.mapping(data, where, required=(), optional=("when", "lane_change", "duration", "speed", "accel"))
    if ("lane_change" in m) == ("speed" in m):
        raise ScenarioError(f"{r.source}: {where}: give exactly one of lane_change or speed")
    when = r.mapping(m.get("when", {}), f"{where}.when", required=(), optional=("time", "ego_x", "gap"))
    trigger = Trigger(**{k: r.number(v, f"{where}.when.{k}") for k, v in when.items()})
    return Maneuver(
        when=trigger,
        lane_change=lane(m["lane_change"], f"{where}.lane_change") if "lane_change" in m else None,
        duration=r.number(m.get("duration", 3.0), f"{where}.duration", minimum=0.1),
        speed=r.number(m["speed"], f"{where}.speed", minimum=0.0) if "speed" in m else None,
        accel=r.number(m.get("accel", 2.0), f"{where}.accel", minimum=0.1),
    )


def _light(r: _Reader, data: Any, where: str) -> TrafficLightSpec:
    m = r.mapping(data, where, required=("id", "stop_line_x", "cycle"))
    cycle = []
    for i, phase in enumerate(r.sequence(m["cycle"], f"{where}.cycle")):
        if not (isinstance(phase, list) and len(phase) == 2 and phase[0] in LIGHT_STATES):
            raise ScenarioError(
                f"{r.source}: {where}.cycle[{i}]: expected [state, seconds] with state one of "
                f"{', '.join(LIGHT_STATES)}, got {phase!r}"
            )
        cycle.append((phase[0], r.number(phase[1], f"{where}.cycle[{i}][1]", minimum=0.1)))
    if not cycle:
        raise ScenarioError(f"{r.source}: {where}.cycle: needs at least one phase")
    return TrafficLightSpec(
        id=r.integer(m["id"], f"{where}.id", minimum=0),
        stop_line_x=r.number(m["stop_line_x"], f"{where}.stop_line_x"),
        cycle=tuple(cycle),
    )


@dataclass
class _Reader:
    """Strict readers for YAML values; every error names the file and the key."""

    source: str

    def fail(self, where: str, message: str) -> ScenarioError:
        return ScenarioError(f"{self.source}: {where}: {message}")

    def mapping(self, value: Any, where: str, required: tuple[str, ...] = (),
                optional: tuple[str, ...] = ()) -> Mapping[str, Any]:
        if not isinstance(value, dict):
            raise self.fail(where, f"expected a mapping, got {type(value).__name__}")
        missing = [k for k in required if k not in value]
        if missing:
            raise self.fail(where, f"missing key(s): {', '.join(missing)}")
        unknown = [k for k in value if k not in required and k not in optional]
        if unknown:
            known = ", ".join((*required, *optional))
            raise self.fail(where, f"unknown key(s): {', '.join(map(str, unknown))} (known: {known})")
        return value

    def sequence(self, value: Any, where: str) -> list:
        if not isinstance(value, list):
            raise self.fail(where, f"expected a list, got {type(value).__name__}")
        return value

    def number(self, value: Any, where: str, minimum: float | None = None, maximum: float | None = None) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.fail(where, f"expected a number, got {value!r}")
        if (minimum is not None and value < minimum) or (maximum is not None and value > maximum):
            raise self.fail(where, f"{value} is outside [{minimum}, {maximum}]")
        return float(value)

    def integer(self, value: Any, where: str, minimum: int | None = None, maximum: int | None = None) -> int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.fail(where, f"expected an integer, got {value!r}")
        if (minimum is not None and value < minimum) or (maximum is not None and value > maximum):
            raise self.fail(where, f"{value} is outside [{minimum}, {maximum}]")
        return value

    def string(self, value: Any, where: str) -> str:
        if not isinstance(value, str):
            raise self.fail(where, f"expected a string, got {value!r}")
        return value
