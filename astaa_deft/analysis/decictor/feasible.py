"""Non-invasive placement (the paper's feasible area, Section IV-A), as pure geometry.

The seed run's ego path is forbidden ground: the ego's footprint along it,
grown by a clearance, every ``dt`` = 2 s window of it being the paper's
R^{P0}(pi(s*), dt) rectangle of the ego's recorded motion. A participant's
whole motion must stay outside all of it — so it never touches the seed
path, whenever it comes — and its waypoints, ``dt`` apart, must each lie in
the kinematic sector of the one before (reachable at its speed and turn-rate
limits, the paper's R(y_t)). Generated placements satisfy both by
construction (rejection sampling of each waypoint in sector minus forbidden
region); a hand-written one that does not is refused with
``PlacementError`` naming where it enters the region.
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass, replace

import numpy as np

from astaa_deft.model.geometry import Box, overlap
from astaa_deft.engine.intercept.actions.participant import Participant, Waypoint
from astaa_deft.analysis.decictor.paths import EgoPath
from astaa_deft.model.errors import AstaaDeftError

DT = 2.0  # s between waypoints, the paper's time step
DEFAULT_CLEARANCE = 0.5  # m, the paper's safe distance
# s the ego would drive on past the seed path's end: a planner plans that far ahead, so a participant
# crossing the road just past the recorded end would change the plan legitimately (found by the
# benchmark with the defect off: a car cutting across the lane 10 m past the goal made the clean
# planner change lanes).
LOOKAHEAD = 5.0
FOOTPRINT_SPACING = 1.0  # m between the seed footprints that tile the swept path (each is 4.6 m + 2 clearances long)
MOTION_SAMPLE = 0.5  # m between checked positions along a participant's motion


class PlacementError(AstaaDeftError, ValueError):
    """A placement that would enter the forbidden region or break its kinematic limits."""

    exit_code = 2  # bad input: the CLI prints it as one line


@dataclass(frozen=True, kw_only=True)
class Kind:
    name: str
    length: float
    width: float
    max_speed: float  # m/s; 0: static only
    max_turn_rate: float = 0.4  # rad/s of heading change between waypoints


KINDS = {
    "cone": Kind(name="cone", length=0.5, width=0.5, max_speed=0.0),
    "barrier": Kind(name="barrier", length=0.6, width=2.0, max_speed=0.0),
    "vehicle": Kind(name="vehicle", length=4.6, width=1.9, max_speed=15.0),
    "pedestrian": Kind(name="pedestrian", length=0.6, width=0.6, max_speed=1.5, max_turn_rate=1.5),
}
STATIC_KINDS = ("cone", "barrier", "vehicle")
MOVING_KINDS = ("vehicle", "pedestrian")


@dataclass(frozen=True)
class Area:
    """Where participants may be placed at all: an axis-aligned rectangle (e.g. the lanes' extent)."""

    x_min: float
    x_max: float
    y_min: float
    y_max: float


class ForbiddenRegion:
    """The seed ego path's swept footprint grown by ``clearance``, tiled by oriented boxes."""

    def __init__(self, seed: EgoPath, dt: float = DT, clearance: float = DEFAULT_CLEARANCE,
                 lookahead: float = LOOKAHEAD):
        if not seed.states:
            raise PlacementError("the seed run has no ego path: nothing to place participants around")
        self.seed = seed
        self.dt = dt
        self.clearance = clearance
        self.boxes = [seed.box(s).grown(clearance) for s in seed.thinned(FOOTPRINT_SPACING)]
        last = seed.states[-1]
        reach = max(last.speed, 1.0) * lookahead  # the path the ego would go on along, past the end
        for k in range(1, int(reach / FOOTPRINT_SPACING) + 1):
            d = k * FOOTPRINT_SPACING
            ahead = Box(last.x + d * math.cos(last.heading), last.y + d * math.sin(last.heading), last.heading,
                        seed.length, seed.width)
            self.boxes.append(ahead.grown(clearance))
        # Bounding circles of the tiles, so a box is tested exactly only against the few tiles near it.
        self._centres = np.array([(b.x, b.y) for b in self.boxes], dtype=float).reshape(-1, 2)
        self._radii = np.array([b.radius for b in self.boxes], dtype=float)

    def window(self, t: float) -> list[Box]:
        """R^{P0}(t, dt): the grown footprints of the ego's recorded motion during [t, t + dt]."""
        return [self.seed.box(s).grown(self.clearance) for s in self.seed.states if t <= s.t <= t + self.dt]

    def hit(self, box: Box) -> Box | None:
        """The forbidden tile ``box`` overlaps, if any."""
        near = np.hypot(self._centres[:, 0] - box.x, self._centres[:, 1] - box.y) < self._radii + box.radius
        for k in np.flatnonzero(near):
            if overlap(self.boxes[k], box) > 0.0:
                return self.boxes[k]
        return None


def motion_boxes(participant: Participant) -> list[tuple[float, Box]]:
    """(time, footprint) along the participant's whole motion, every MOTION_SAMPLE metres (or its pose)."""
    points = participant.waypoints()
    out = [(points[0].t, _box(participant, points[0].t))]
    for a, b in zip(points, points[1:], strict=False):
        steps = max(1, math.ceil(math.hypot(b.x - a.x, b.y - a.y) / MOTION_SAMPLE))
        for k in range(1, steps + 1):
            t = a.t + (b.t - a.t) * k / steps
            out.append((t, _box(participant, t - 1e-9 if k == steps else t)))
    return out


def _box(participant: Participant, t: float) -> Box:
    pose = participant.pose_at(t)
    return Box(pose.x, pose.y, pose.heading, participant.length, participant.width)


def check_placement(participant: Participant, region: ForbiddenRegion) -> None:
    """Refuse (PlacementError) a participant that enters the forbidden region or leaves its sectors."""
    for t, box in motion_boxes(participant):
        tile = region.hit(box)
        if tile is not None:
            raise PlacementError(
                f"participant {participant.id} enters the forbidden region at t={t:.2f} s, ({box.x:.2f}, "
                f"{box.y:.2f}): within {region.clearance:g} m of the seed ego path near ({tile.x:.2f}, "
                f"{tile.y:.2f})", )
    kind = KINDS.get(participant.kind)
    if kind is None or participant.static:
        return
    points = participant.waypoints()
    heading = None
    for k, (a, b) in enumerate(zip(points, points[1:], strict=False), start=1):
        duration = b.t - a.t
        distance = math.hypot(b.x - a.x, b.y - a.y)
        if distance > kind.max_speed * duration + 1e-9:
            raise PlacementError(f"participant {participant.id}: waypoint {k} is outside its kinematic sector: "
                                 f"{distance:.1f} m in {duration:g} s is faster than {kind.max_speed:g} m/s")
        if distance > 0.0:
            new_heading = math.atan2(b.y - a.y, b.x - a.x)
            if heading is not None:
                turn = abs(math.atan2(math.sin(new_heading - heading), math.cos(new_heading - heading)))
                if turn > kind.max_turn_rate * duration + 1e-9:
                    raise PlacementError(f"participant {participant.id}: waypoint {k} is outside its kinematic "
                                         f"sector: a turn of {math.degrees(turn):.0f}° in {duration:g} s")
            heading = new_heading


def is_feasible(participant: Participant, region: ForbiddenRegion) -> bool:
    try:
        check_placement(participant, region)
    except PlacementError:
        return False
    return True


# ---------------------------------------------------------------- generation

TRIES = 60


def sample_participant(rng: random.Random, participant_id: int, region: ForbiddenRegion, area: Area,
                       *, moving: bool | None = None) -> Participant | None:
    """A random participant wholly outside the region (None if none was found in TRIES draws)."""
    if moving is None:
        moving = rng.random() < 0.5
    kind = KINDS[rng.choice(MOVING_KINDS if moving else STATIC_KINDS)]
    start, end = region.seed.start, region.seed.end
    for _ in range(TRIES):
        x, y = rng.uniform(area.x_min, area.x_max), rng.uniform(area.y_min, area.y_max)
        heading = rng.choice((0.0, math.pi)) + rng.gauss(0.0, 0.15) if kind.name == "vehicle" \
            else rng.uniform(-math.pi, math.pi)
        placed = Participant(id=participant_id, kind=kind.name, x=round(x, 2), y=round(y, 2), heading=round(heading, 3),
                             length=kind.length, width=kind.width,
                             t=round(rng.uniform(start, start + 0.5 * (end - start)), 1))
        if region.hit(_box(placed, placed.t)) is not None:
            continue
        if moving:
            placed = _extend(rng, placed, kind, region, area=area, end=end)
        if is_feasible(placed, region):
            return placed
    return None


def _extend(rng: random.Random, placed: Participant, kind: Kind, region: ForbiddenRegion, *, area: Area,
            end: float) -> Participant:
    """Waypoints every dt, each drawn from the sector of the last one minus the region (Algorithm 2, Adding)."""
    heading, speed = placed.heading, rng.uniform(0.3, 1.0) * kind.max_speed
    path: list[Waypoint] = []
    last = Waypoint(placed.t, placed.x, placed.y)
    while last.t < end:
        for _ in range(TRIES // 3):
            turn = rng.uniform(-1.0, 1.0) * kind.max_turn_rate * region.dt
            v = min(kind.max_speed, max(0.0, speed + rng.gauss(0.0, 1.0)))
            h = heading + turn
            nxt = Waypoint(round(last.t + region.dt, 3), round(last.x + v * region.dt * math.cos(h), 2),
                           round(last.y + v * region.dt * math.sin(h), 2))
            # Only the new segment needs checking: the path up to ``last`` is clear already.
            segment = replace(placed, x=last.x, y=last.y, heading=h, t=last.t, path=(nxt,))
            if area.y_min <= nxt.y <= area.y_max and all(region.hit(box) is None
                                                         for _, box in motion_boxes(segment)):
                path.append(nxt)
                heading, speed, last = h, v, nxt
                break
        else:
            break  # the sector holds no free point: it stops where it is
    return replace(placed, path=tuple(path))


def perturb(rng: random.Random, participant: Participant, region: ForbiddenRegion, area: Area,
            *, scale: float = 2.0) -> Participant | None:
    """The participant moved a little (pose, start time, waypoints, speed); None if no feasible variant."""
    for _ in range(TRIES // 3):
        dx, dy = rng.gauss(0.0, scale), rng.gauss(0.0, 0.5 * scale)
        dt = rng.gauss(0.0, 0.5)
        stretch = math.exp(rng.gauss(0.0, 0.15))  # faster or slower along the same path
        t0 = max(region.seed.start, participant.t + dt)
        path = tuple(Waypoint(round(t0 + (w.t - participant.t) * stretch, 3), round(w.x + dx, 2),
                              round(w.y + dy, 2)) for w in participant.path)
        heading = participant.heading + rng.gauss(0.0, 0.3)  # how it stands (a static one) or first faces
        candidate = replace(participant, x=round(participant.x + dx, 2), y=round(participant.y + dy, 2),
                            heading=round(math.atan2(math.sin(heading), math.cos(heading)), 3), t=round(t0, 3),
                            path=path)
        if area.x_min <= candidate.x <= area.x_max and area.y_min <= candidate.y <= area.y_max \
                and is_feasible(candidate, region):
            return candidate
    return None
