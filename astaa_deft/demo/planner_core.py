"""The demo planner: a deterministic sampling planner, as a pure function of (frame, state).

``Planner.step(frame)`` takes the newest message of each input channel, keyed
by the spec's channel names (``routing``, ``localization``, ``traffic_light``,
``prediction``), and returns the exact ``demo/planning/trajectory`` message.
The prediction is the trigger: its stamp is "now". Nothing else is read — no
clock, no randomness, no iteration over unordered containers — so a fresh
``Planner`` fed the same frames in the same order returns the same bytes.
That is what DeFT replays (factory: ``astaa_deft.demo.planner_core:Planner``).

Each cycle it samples candidate plans = target lane (current, left, right) ×
speed profile (reach a fraction of the cruise speed at some rate, or stop at
a line), drops those that hit a predicted obstacle or run a light, and picks
the cheapest by speed, comfort, headway, lane and consistency costs. State
kept across cycles: the previous trajectory, the lane decision (hysteresis),
the lights it has committed to stop for, the last good speed limit.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple
from collections.abc import Mapping, Sequence

from astaa_deft.demo import messages, vehicle
from astaa_deft.demo.frenet import (DT, STEPS, LateralPath, SpeedProfile, forecast_boxes, interpolate,
                     speed_profile, stop_profile)
from astaa_deft.demo.geometry import Box, boxes_overlap, wrap_angle

INPUT_CHANNELS = ("routing", "localization", "traffic_light", "prediction")
TRIGGER_CHANNEL = "prediction"

MAX_CRUISE_SPEED = 20.0  # m/s the planner would drive if nothing limited it
# The planning clock (not a seeded defect: both modes). A trigger stamp that is not finite, more than
# CLOCK_BACK_TOLERANCE before the clock or more than CLOCK_MAX_STEP after it is a corrupted message, not
# time: the clock steps on by one trigger period instead (a held bad stamp keeps the plans coming). Any
# other stamp is the cycle's time, as it always was: a frame replayed out of order (DeFT trying a
# neighbouring trigger) plans exactly as the recorded run did.
TRIGGER_PERIOD = 0.1  # s, prediction's
CLOCK_BACK_TOLERANCE = 0.5  # s: a few triggers (the stamp family's jump back is 1 s)
CLOCK_MAX_STEP = 60.0  # s: longer than any demo run, so a real gap (triggers lost for a while) is followed
FALLBACK_SPEED_LIMIT = 8.0  # m/s, until a usable limit arrives (defects off)
# The demo vehicle's operational design domain: urban roads, none signed above 54 km/h. A routing limit
# beyond it is a corrupted message, not a road (defects off: ignored like a non-finite one).
ODD_MAX_SPEED_LIMIT = 15.0  # m/s
SPEED_LIMIT_MARGIN = 0.3  # m/s below the limit, so speed-control overshoot stays legal
COMFORT_DECEL = 3.0  # m/s²
MAX_PLAN_DECEL = 6.0  # m/s², the hardest braking it plans (the brakes can do more)
SPEED_FRACTIONS = (1.0, 0.75, 0.5, 0.25, 0.0)  # of the cruise speed
ACCEL_RATES = (1.0, 2.0)
DECEL_RATES = (1.0, 2.5, 4.0, MAX_PLAN_DECEL)
LANE_CHANGE_TIME = 3.0  # s of travel a lane change takes…
LANE_CHANGE_MIN_LENGTH = 20.0  # …but never shorter than this, m
MAX_ENTRY_SLOPE = 0.5  # dl/ds the lateral path may start with
# Safety margins added to the ego footprint for the hard collision check (total, m).
MARGIN_LENGTH, MARGIN_WIDTH = 1.0, 0.4
STOP_LINE_BUFFER = 1.0  # m between the front bumper and a stop line when stopped
ROAD_END_BUFFER = 5.0  # m

W_SPEED = 1.0  # per (m/s)² s off the cruise speed
W_ACCEL = 0.5  # per (m/s²)² s
W_HEADWAY = 4.0  # per m² s of missing gap to a leader
HEADWAY_TIME, MIN_GAP = 1.2, 3.0  # desired gap = MIN_GAP + HEADWAY_TIME * v
W_SIDE, SIDE_CLEARANCE = 100.0, 1.5  # per m² s of lateral gap below SIDE_CLEARANCE to a car alongside
W_CONSISTENCY = 0.2  # per (m/s)² s of speed change against the previous plan
LANE_CHANGE_COST = 10.0
LANE_SWITCH_COST = 10.0  # changing the lane decision: the hysteresis
OFF_GOAL_LANE_COST = 25.0  # per lane away from the goal lane
# SEEDED DEFECT 5 (defects on, a decision defect): traffic furniture (a cone or a barrier) standing
# on the shoulder, off the lanes, is taken for wider than it is: STANDING_WIDEN m more on each side
# across the road, whatever way it is turned, in the hard check — so one within ~1 m of the lane edge
# closes the lane: a needless lane change. While passing such an object the ego also slows, the
# more the closer it stands (down to CAUTION_SPEED_SHARE of cruise beside it, none CAUTION_GAP m
# away): harmless in itself, it is the gradient a guided search can climb towards the lane change.
STANDING_KINDS = ("cone", "barrier")
STANDING_WIDEN = 2.2  # m
CAUTION_GAP, CAUTION_AHEAD, CAUTION_SPEED_SHARE = 6.0, 40.0, 0.5


class Start(NamedTuple):
    s: float
    l: float  # noqa: E741 - the Frenet lateral offset is called l, as in (s, l)
    slope: float  # dl/ds
    v: float


class Candidate(NamedTuple):
    lane: int
    profile: SpeedProfile


class Road(NamedTuple):
    lanes: int
    lane_width: float
    length: float
    goal_lane: int

    def center(self, lane: int) -> float:
        return lane * self.lane_width

    def nearest_lane(self, l: float) -> int:  # noqa: E741 - Frenet (s, l)
        return max(0, min(self.lanes - 1, int(round(l / self.lane_width))))


class Planner:
    def __init__(self, defects: bool = True):
        self.defects = defects
        self.seq = 0
        self.lane_decision: int | None = None
        self.lateral: LateralPath | None = None  # the committed path towards lane_decision
        self.previous: list[messages.TrajectoryPoint] | None = None
        self.stopping_for: set[int] = set()  # light ids it committed to stop for
        self.speed_limit: float | None = None  # last usable one (defects off)
        self.road: Road | None = None  # last usable routing
        self.clock: float | None = None  # the time of the last cycle

    # --- the cycle ---------------------------------------------------------
    def step(self, frame: Mapping[str, dict]) -> dict[str, Any]:
        stamp = messages.header(frame[TRIGGER_CHANNEL]).stamp
        now = self._tick(stamp)
        if now is None:  # no usable time yet: nothing can be planned
            self.seq += 1
            return self._message(stamp, frame, [], self.lane_decision, "no_plan")
        routing = messages.routing(frame["routing"])
        road = self._road(routing)
        start = self._start(messages.localization(frame["localization"]), now)
        lights = messages.traffic_lights(frame["traffic_light"]) if "traffic_light" in frame else []
        _, predicted = messages.prediction(frame[TRIGGER_CHANNEL])
        self.seq += 1
        if road is None or start is None:
            self.previous = self.lateral = None
            return self._message(now, frame, [], self.lane_decision, "no_plan")

        cruise = self._cruise_speed(routing.speed_limit)
        current_lane = road.nearest_lane(start.l)
        obstacles, standing = [], []
        for obstacle in predicted:
            boxes = forecast_boxes(obstacle, now)
            if boxes is None:
                continue
            obstacles.append(boxes)
            if self.defects and obstacle.kind in STANDING_KINDS and _standing(boxes) and _off_road(boxes[0], road):
                standing.append(boxes)
        hard = [_widened(boxes) if any(boxes is b for b in standing) else boxes for boxes in obstacles]
        stop_lines = self._stop_lines(lights, road, start)
        previous_v = self._previous_speeds(now)

        best_key, best = None, None
        for lane in self._candidate_lanes(road, current_lane):
            path = self._lateral_path(lane, road, start)
            for candidate in self._candidates(lane, start, cruise, stop_lines):
                points = _points(now, start, path, candidate.profile)
                first_violation = self._first_violation(points, hard, stop_lines)
                cost = self._cost(candidate, points, obstacles, cruise, stop_lines, road, current_lane,
                                  previous_v, standing)
                # Feasible plans by cost; if none is, the one that stays safe longest.
                key = (first_violation is not None, -(first_violation or 0), cost)
                if best_key is None or key < best_key:
                    best_key, best = key, (candidate, points, path)

        if best is None or best_key is None:  # the candidate set always holds keeping the current lane
            raise RuntimeError("the planner had no candidate to choose from")
        candidate, points, path = best
        behavior = self._behavior(candidate, current_lane, cruise, emergency=best_key[0])
        self.lane_decision, self.lateral = candidate.lane, path
        self.previous = [messages.TrajectoryPoint(**p) for p in points]
        return self._message(now, frame, points, candidate.lane, behavior)

    # --- inputs --------------------------------------------------------------
    def _tick(self, stamp: float) -> float | None:
        """This cycle's time: the trigger's stamp if plausible, else the clock one period on (None before
        any usable stamp)."""
        last = self.clock
        if math.isfinite(stamp) and (last is None or last - CLOCK_BACK_TOLERANCE <= stamp <= last + CLOCK_MAX_STEP):
            self.clock = stamp
        elif last is not None:
            self.clock = last + TRIGGER_PERIOD
        return self.clock

    def _cruise_speed(self, limit: float) -> float:
        if not self.defects:
            # A limit that is not a positive finite number, or one no road of the ODD has, is no limit at
            # all: keep the last good one.
            if math.isfinite(limit) and 0.0 < limit <= ODD_MAX_SPEED_LIMIT:
                self.speed_limit = limit
            limit = self.speed_limit if self.speed_limit is not None else FALLBACK_SPEED_LIMIT
        cruise = MAX_CRUISE_SPEED
        allowed = limit - SPEED_LIMIT_MARGIN
        if cruise > allowed:  # SEEDED DEFECT 1 (defects on): NaN compares false, the limit stops applying
            cruise = allowed
        return max(cruise, 0.0)

    def _road(self, routing: messages.Routing) -> Road | None:
        usable = (1 <= routing.lane_count <= 8 and math.isfinite(routing.lane_width)
                  and 2.0 <= routing.lane_width <= 6.0 and math.isfinite(routing.road_length)
                  and routing.road_length > 0.0)
        if usable:
            goal_lane = max(0, min(routing.lane_count - 1, routing.goal_lane))
            self.road = Road(routing.lane_count, routing.lane_width, routing.road_length, goal_lane)
        return self.road

    def _start(self, loc: messages.Localization, now: float) -> Start | None:
        """Where the plan starts: the measured state, or the previous plan if the measurement is unusable."""
        if all(math.isfinite(v) for v in (loc.x, loc.y, loc.heading, loc.speed)):
            x, y, heading, v = loc.x, loc.y, loc.heading, loc.speed
        elif self.previous:
            times = [p.t for p in self.previous]
            x, y, heading, v = (interpolate(times, [getattr(p, f) for p in self.previous], now)
                                for f in ("x", "y", "heading", "v"))
        else:
            return None
        slope = max(-MAX_ENTRY_SLOPE, min(MAX_ENTRY_SLOPE, math.tan(wrap_angle(heading))))
        return Start(s=x, l=y, slope=slope, v=max(0.0, min(v, 2.0 * MAX_CRUISE_SPEED)))

    def _stop_lines(self, lights: list[messages.TrafficLight], road: Road, start: Start) -> list[float]:
        """Station limits for the front bumper that the plan must not pass, ascending (never empty)."""
        front = start.s + 0.5 * vehicle.LENGTH
        lines = [road.length - ROAD_END_BUFFER]
        for light in sorted(lights, key=lambda light: light.id):
            if light.state == "green" or not math.isfinite(light.stop_line_x):
                self.stopping_for.discard(light.id)
                continue
            if front >= light.stop_line_x:
                continue  # already over the line: clear the junction
            distance = max(light.stop_line_x - STOP_LINE_BUFFER - front, 0.0)
            needed = start.v * start.v / (2.0 * distance) if distance > 0.0 else math.inf
            # Red: stop if at all possible. Yellow (or unknown): stop if comfortable, and
            # once committed keep stopping, so the decision cannot flip-flop.
            limit = MAX_PLAN_DECEL if light.state == "red" else COMFORT_DECEL
            if needed <= limit or light.id in self.stopping_for or start.v < 0.5:
                self.stopping_for.add(light.id)
                lines.append(light.stop_line_x)
        return sorted(lines)

    def _previous_speeds(self, now: float) -> list[float] | None:
        if not self.previous:
            return None
        times = [p.t for p in self.previous]
        speeds = [p.v for p in self.previous]
        return [interpolate(times, speeds, now + k * DT) for k in range(STEPS + 1)]

    # --- candidates ----------------------------------------------------------
    def _lateral_path(self, lane: int, road: Road, start: Start) -> LateralPath:
        """The committed lateral path if it still leads to ``lane`` and the ego is on it, else a new one.

        Re-planning the lane change from scratch every cycle would push its end
        ahead forever (and overshoot); keeping the committed path lets it finish.
        """
        kept = self.lateral
        if kept is not None and kept.l1 == road.center(lane) and abs(kept.at(start.s)[0] - start.l) < 0.75:
            return kept
        return LateralPath(start.s, start.l, start.slope, road.center(lane),
                           max(LANE_CHANGE_MIN_LENGTH, start.v * LANE_CHANGE_TIME))

    def _candidate_lanes(self, road: Road, current: int) -> list[int]:
        lanes = {current - 1, current, current + 1}
        if self.lane_decision is not None:
            lanes.add(self.lane_decision)
        return sorted(lane for lane in lanes if 0 <= lane < road.lanes)

    def _candidates(self, lane: int, start: Start, cruise: float, stop_lines: list[float]) -> list[Candidate]:
        candidates = []
        for fraction in SPEED_FRACTIONS:
            target = fraction * cruise
            rates = ACCEL_RATES if target > start.v else DECEL_RATES
            for rate in rates:
                profile = speed_profile(start.s, start.v, target, rate, f"to {target:.2f} at {rate}")
                candidates.append(Candidate(lane, profile))
        front = start.s + 0.5 * vehicle.LENGTH
        for line in stop_lines:
            distance = line - STOP_LINE_BUFFER - front
            if distance > start.v * STEPS * DT + 1.0:
                break  # out of reach within the horizon; so are the lines after it
            if distance < 0.3:  # already inside the buffer: creep no further than just short of the line
                distance = max(line - front - 0.1, 0.0)
            profile = stop_profile(start.s, start.v, distance, MAX_PLAN_DECEL)
            candidates.append(Candidate(lane, profile))
        return candidates

    def _first_violation(self, points: list[dict], obstacles: list[list[Box]], stop_lines: list[float]) -> int | None:
        """The first step at which the plan hits an obstacle or passes a stop line."""
        first_line = stop_lines[0]
        for k in range(1, STEPS + 1):
            p = points[k]
            if p["x"] + 0.5 * vehicle.LENGTH > first_line + 0.05:
                return k
            ego = Box(p["x"], p["y"], p["heading"], vehicle.LENGTH + MARGIN_LENGTH, vehicle.WIDTH + MARGIN_WIDTH)
            for boxes in obstacles:
                if boxes_overlap(ego, boxes[k]):
                    return k
        # Past the horizon the plan must still be able to stop comfortably before the line;
        # without this the planner would crawl towards a red light instead of stopping at it.
        end = points[-1]
        if end["x"] + 0.5 * vehicle.LENGTH + end["v"] ** 2 / (2.0 * COMFORT_DECEL) > first_line + 0.05:
            return STEPS
        return None

    def _cost(self, candidate: Candidate, points: list[dict], obstacles: list[list[Box]], cruise: float,
              stop_lines: list[float], road: Road, current_lane: int, previous_v: list[float] | None,
              standing: Sequence[list[Box]] = ()) -> float:
        cost = 0.0
        stop_at = stop_lines[0] - STOP_LINE_BUFFER
        standing_half_y = [_half_extents(boxes[0])[1] for boxes in standing]  # it stands still: one extent
        for k, p in enumerate(points):
            v = p["v"]
            # The speed to aim for: cruise, or less where a comfortable stop at the line demands it
            # (otherwise the best-looking plans crawl towards a red light instead of stopping at it).
            room = max(0.0, stop_at - p["x"] - 0.5 * vehicle.LENGTH)
            reference = min(cruise, math.sqrt(2.0 * COMFORT_DECEL * room))
            for boxes, half_y in zip(standing, standing_half_y, strict=True):  # defect 5: caution, the closer the more
                box = boxes[k]
                side_gap = abs(box.y - p["y"]) - 0.5 * vehicle.WIDTH - half_y
                if side_gap < CAUTION_GAP and -0.5 * (vehicle.LENGTH + box.length) < box.x - p["x"] < CAUTION_AHEAD:
                    share = CAUTION_SPEED_SHARE + (1.0 - CAUTION_SPEED_SHARE) * max(side_gap, 0.0) / CAUTION_GAP
                    reference = min(reference, share * cruise)
            cost += (W_SPEED * (v - reference) ** 2 + W_ACCEL * p["a"] ** 2) * DT
            if previous_v is not None:
                cost += W_CONSISTENCY * (v - previous_v[k]) ** 2 * DT
            desired_gap = MIN_GAP + HEADWAY_TIME * v
            for boxes in obstacles:
                box = boxes[k]
                ahead = box.x - p["x"]
                side_gap = abs(box.y - p["y"]) - 0.5 * (vehicle.WIDTH + box.width)
                if side_gap < 0.3:  # in our corridor: keep a time headway behind it
                    gap = ahead - 0.5 * (vehicle.LENGTH + box.length)
                    if ahead > 0.0 and gap < desired_gap:
                        cost += W_HEADWAY * (desired_gap - gap) ** 2 * DT
                elif side_gap < SIDE_CLEARANCE and abs(ahead) < 0.5 * (vehicle.LENGTH + box.length) + 5.0:
                    cost += W_SIDE * (SIDE_CLEARANCE - side_gap) ** 2 * DT  # alongside: do not squeeze by
        if candidate.lane != current_lane:
            cost += LANE_CHANGE_COST
        if self.lane_decision is not None and candidate.lane != self.lane_decision:
            cost += LANE_SWITCH_COST
        cost += OFF_GOAL_LANE_COST * abs(candidate.lane - road.goal_lane)
        return cost

    @staticmethod
    def _behavior(candidate: Candidate, current_lane: int, cruise: float, emergency: bool) -> str:
        if emergency:
            return "emergency_stop"
        if candidate.lane != current_lane:
            return "lane_change"
        if candidate.profile.v[-1] < 0.1:
            return "stop"
        if candidate.profile.v[-1] < cruise - 0.5:
            return "follow"
        return "cruise"

    # --- output --------------------------------------------------------------
    def _message(self, now: float, frame: Mapping[str, dict], points: list[dict], lane: int | None,
                 behavior: str) -> dict[str, Any]:
        return {
            "header": {"seq": self.seq, "stamp": now},
            "points": points,
            "decision": {"lane": lane if lane is not None else -1, "behavior": behavior},
            # Ground truth for evaluating DeFT's frame reconstruction; nothing in the stack reads it.
            # Sorted so the bytes never depend on the order the caller built the frame in.
            "debug": {"inputs": {name: messages.header(frame[name]).seq for name in sorted(frame)}},
        }


def _standing(boxes: list[Box]) -> bool:
    return abs(boxes[-1].x - boxes[0].x) + abs(boxes[-1].y - boxes[0].y) < 0.1


def _off_road(box: Box, road: Road) -> bool:
    return box.y < -0.5 * road.lane_width or box.y > road.center(road.lanes - 1) + 0.5 * road.lane_width


def _half_extents(box: Box) -> tuple[float, float]:
    """Half its extent along the road (x) and across it (y), as turned."""
    c, s = abs(math.cos(box.heading)), abs(math.sin(box.heading))
    return 0.5 * (box.length * c + box.width * s), 0.5 * (box.length * s + box.width * c)


def _widened(boxes: list[Box]) -> list[Box]:
    """Defect 5: the footprint's extent across the road grown by STANDING_WIDEN on each side, whatever its heading."""
    out = []
    for b in boxes:
        half_x, half_y = _half_extents(b)
        out.append(Box(b.x, b.y, 0.0, 2.0 * half_x, 2.0 * (half_y + STANDING_WIDEN)))
    return out


def _points(now: float, start: Start, path: LateralPath, profile: SpeedProfile) -> list[dict]:
    points = []
    for k in range(STEPS + 1):
        s = profile.s[k]
        l, slope = path.at(s)  # noqa: E741 - Frenet (s, l)
        points.append({"t": round(now + k * DT, 9), "x": s, "y": l, "heading": math.atan(slope),
                       "v": profile.v[k], "a": profile.a[k]})
    return points
