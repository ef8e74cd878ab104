"""The simulated world: ego kinematics, scripted NPCs, traffic lights, collisions, goal.

Pure and single threaded: ``World.step(dt, steering, acceleration)`` advances it, the
``*_body`` methods describe it as message bodies (without headers). The
simulator process decides when to step and what to publish.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any
from collections.abc import Callable

from astaa_deft.demo import vehicle
from astaa_deft.demo.geometry import Box, separation, smoothstep5, wrap_angle
from astaa_deft.demo.scenario import Maneuver, ObjectSpec, Scenario


@dataclass(kw_only=True)
class Ego:
    """Kinematic bicycle model on the rear axle; everything published refers to the box centre."""

    rear_x: float
    rear_y: float
    heading: float
    speed: float
    acceleration: float = 0.0
    yaw_rate: float = 0.0

    def step(self, dt: float, steering: float, acceleration: float) -> None:
        steering = max(-vehicle.MAX_STEERING, min(vehicle.MAX_STEERING, steering))
        acceleration = max(-vehicle.MAX_DECELERATION, min(vehicle.MAX_ACCELERATION, acceleration))
        self.yaw_rate = self.speed * math.tan(steering) / vehicle.WHEELBASE
        self.rear_x += self.speed * math.cos(self.heading) * dt
        self.rear_y += self.speed * math.sin(self.heading) * dt
        self.heading += self.yaw_rate * dt
        new_speed = max(0.0, self.speed + acceleration * dt)  # brakes stop the car, never reverse it
        self.acceleration = (new_speed - self.speed) / dt
        self.speed = new_speed

    @property
    def x(self) -> float:
        return self.rear_x + 0.5 * vehicle.WHEELBASE * math.cos(self.heading)

    @property
    def y(self) -> float:
        return self.rear_y + 0.5 * vehicle.WHEELBASE * math.sin(self.heading)

    def box(self) -> Box:
        return Box(self.x, self.y, self.heading, vehicle.LENGTH, vehicle.WIDTH)


@dataclass
class LaneChange:
    start_time: float
    duration: float
    from_y: float
    to_y: float


class WorldObject:
    """A static obstacle or an NPC that follows its scripted maneuvers."""

    def __init__(self, object_id: int, spec: ObjectSpec, lane_center: float):
        self.id = object_id
        self.spec = spec
        self.x = spec.x
        self.y = lane_center + spec.offset
        self.heading = spec.heading
        self.speed = spec.speed
        self.vy = 0.0
        self.target_speed = spec.speed
        self.accel = 0.0
        self.lane_change: LaneChange | None = None
        self.pending: list[Maneuver] = list(spec.maneuvers)

    def box(self) -> Box:
        return Box(self.x, self.y, self.heading, self.spec.length, self.spec.width)

    def step(self, t: float, dt: float, ego: Ego, lane_center: Callable[[int], float]) -> None:
        for maneuver in [m for m in self.pending if self._triggered(m, t, ego)]:
            self.pending.remove(maneuver)
            if maneuver.lane_change is not None:
                self.lane_change = LaneChange(t, maneuver.duration, self.y, lane_center(maneuver.lane_change))
            elif maneuver.speed is not None:
                self.target_speed, self.accel = maneuver.speed, maneuver.accel
        if self.speed != self.target_speed:
            change = self.accel * dt
            self.speed = (min(self.target_speed, self.speed + change) if self.target_speed > self.speed
                          else max(self.target_speed, self.speed - change))
        self.x += self.speed * dt  # NPCs drive along the road (+x); only static obstacles sit at an angle
        if self.lane_change is not None:
            lc = self.lane_change
            shape, slope = smoothstep5((t + dt - lc.start_time) / lc.duration)
            self.y = lc.from_y + (lc.to_y - lc.from_y) * shape
            self.vy = (lc.to_y - lc.from_y) * slope / lc.duration
            if shape >= 1.0:
                self.lane_change, self.vy = None, 0.0
        if self.speed > 0.0:
            self.heading = math.atan2(self.vy, self.speed)

    def _triggered(self, m: Maneuver, t: float, ego: Ego) -> bool:
        w = m.when
        return ((w.time is None or t >= w.time)
                and (w.ego_x is None or ego.x >= w.ego_x)
                and (w.gap is None or 0.0 <= self.x - ego.x <= w.gap))

    def perception_body(self) -> dict[str, Any]:
        return {
            "id": self.id, "kind": self.spec.kind,
            "x": self.x, "y": self.y, "heading": self.heading,
            "vx": self.speed, "vy": self.vy,
            "length": self.spec.length, "width": self.spec.width,
        }


NOTHING_NEAR = 1000.0  # min_clearance reported when the scenario has no objects at all


class World:
    def __init__(self, scenario: Scenario):
        self.scenario = scenario
        road = scenario.road
        self.time = 0.0
        self.steps = 0
        self.ego = Ego(
            rear_x=scenario.ego_x - 0.5 * vehicle.WHEELBASE,
            rear_y=road.lane_center(scenario.ego_lane),
            heading=0.0,
            speed=scenario.ego_speed,
        )
        specs = scenario.obstacles + scenario.npcs
        self.objects = [WorldObject(i + 1, spec, road.lane_center(spec.lane)) for i, spec in enumerate(specs)]
        self.collision_with = ""
        self.goal_time: float | None = None
        self.min_clearance = math.inf

    @property
    def collided(self) -> bool:
        return bool(self.collision_with)

    @property
    def done(self) -> bool:
        return self.collided or self.goal_time is not None or self.time >= self.scenario.time_limit

    def step(self, dt: float, steering: float, acceleration: float) -> None:
        for obj in self.objects:
            obj.step(self.time, dt, self.ego, self.scenario.road.lane_center)
        self.ego.step(dt, steering, acceleration)
        self.steps += 1
        # Computed, not accumulated, so every run shares the same time grid (0.01, 0.02, …).
        self.time = round(self.steps * dt, 9)
        self._judge()

    def _judge(self) -> None:
        """Latch the first collision and the goal arrival; track the closest approach."""
        ego_box = self.ego.box()
        for obj in self.objects:
            gap = separation(ego_box, obj.box())
            self.min_clearance = min(self.min_clearance, gap)
            if not self.collided and gap <= 0.0:
                self.collision_with = obj.spec.name
        if not self.collided and self._off_road(ego_box):
            self.collision_with = "road_edge"
        if self.goal_time is None and not self.collided and self.ego.x >= self.scenario.goal_x:
            self.goal_time = self.time

    def _off_road(self, box: Box) -> bool:
        road = self.scenario.road
        half_lane = 0.5 * road.lane_width
        c, s = math.cos(box.heading), math.sin(box.heading)
        corner_ys = [box.y + a * 0.5 * box.length * s + b * 0.5 * box.width * c
                     for a in (-1, 1) for b in (-1, 1)]
        return min(corner_ys) < -half_lane or max(corner_ys) > road.lane_center(road.lanes - 1) + half_lane

    # --- message bodies -------------------------------------------------
    def localization_body(self) -> dict[str, Any]:
        e = self.ego
        return {"x": e.x, "y": e.y, "heading": wrap_angle(e.heading), "speed": e.speed,
                "acceleration": e.acceleration, "yaw_rate": e.yaw_rate}

    def obstacles_body(self) -> dict[str, Any]:
        return {"obstacles": [obj.perception_body() for obj in self.objects]}

    def traffic_light_body(self) -> dict[str, Any]:
        return {"lights": [{"id": light.id, "state": light.state_at(self.time), "stop_line_x": light.stop_line_x}
                           for light in self.scenario.traffic_lights]}

    def routing_body(self) -> dict[str, Any]:
        sc = self.scenario
        return {"lane_count": sc.road.lanes, "lane_width": sc.road.lane_width, "road_length": sc.road.length,
                "goal": {"x": sc.goal_x, "lane": sc.goal_lane}, "speed_limit": sc.speed_limit}

    def status_body(self, state: str) -> dict[str, Any]:
        return {
            "scenario": self.scenario.name, "state": state, "sim_time": self.time,
            "ego_x": self.ego.x, "ego_y": self.ego.y, "ego_speed": self.ego.speed,
            "speed_limit": self.scenario.speed_limit,
            "collision": self.collided, "collision_with": self.collision_with,
            "goal_reached": self.goal_time is not None,
            "goal_time": self.goal_time if self.goal_time is not None else -1.0,
            "min_clearance": min(self.min_clearance, NOTHING_NEAR),
            "done": self.done,
        }

