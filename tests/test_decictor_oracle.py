"""Decictor's pure logic on crafted paths: the lane-grid consistency oracle, the feedback distances and
the non-invasive placement region (refusal with a clear error; generated placements always outside)."""

from __future__ import annotations

import math
import random

import pytest

from astaa_deft.analysis.decictor.feasible import Area, ForbiddenRegion, PlacementError, check_placement, perturb, \
    sample_participant
from astaa_deft.analysis.decictor.oracle import LaneGrid, RunObservation, consistency, judge, straight_lanes, touches
from astaa_deft.analysis.decictor.paths import EgoPath, EgoState, behaviour_mmd, path_distance
from astaa_deft.engine.intercept.actions.participant import Participant, Waypoint

LANES = straight_lanes(2, 3.5, 300.0)
GRID = LaneGrid(LANES)


def straight(y: float = 0.0, x0: float = 10.0, x1: float = 130.0, speed: float = 12.0) -> EgoPath:
    n = int((x1 - x0) / (speed * 0.1))
    return EgoPath(tuple(EgoState(t=k * 0.1, x=x0 + k * speed * 0.1, y=y, heading=0.0,
                                  speed=speed) for k in range(n + 1)))


def detour(x_out: float, x_back: float, y_off: float = 3.5, speed: float = 12.0) -> EgoPath:
    """Straight in lane 0, a smooth change to y_off between x_out and x_out+20, back after x_back."""
    states = []
    for k in range(int(120 / (speed * 0.1)) + 1):
        x = 10.0 + k * speed * 0.1

        def ramp(u: float) -> float:
            u = min(1.0, max(0.0, u))
            return u * u * (3 - 2 * u)

        y = y_off * (ramp((x - x_out) / 20.0) - ramp((x - x_back) / 20.0))
        states.append(EgoState(t=k * 0.1, x=x, y=y, heading=0.0, speed=speed))
    return EgoPath(tuple(states))


def test_identical_and_wobbling_paths_are_consistent():
    seed = straight()
    assert consistency(seed, seed, GRID).dissimilarity == 0.0
    wobble = EgoPath(tuple(EgoState(t=s.t, x=s.x, y=0.6 * math.sin(s.x / 7.0), heading=0.0,
                                    speed=s.speed) for s in seed.states))
    result = consistency(seed, wobble, GRID)
    assert result.consistent and result.worst_lane == "0"


def test_a_detour_through_the_next_lane_is_inconsistent_on_that_lane():
    result = consistency(straight(), detour(50.0, 80.0), GRID)
    assert not result.consistent
    assert result.worst_lane == "1" and result.dissimilarity == 1.0  # the seed never used lane 1
    lane0 = next(s for s in result.lanes if s.lane == "0")
    assert lane0.jaccard > 0.6  # the own lane alone would not have told


def test_a_brush_of_the_next_lane_under_five_percent_is_dropped():
    # The centre crosses into lane 1 for ~4 m of 120: 2-3 cells of ~60, under 5 %.
    brush = EgoPath(tuple(EgoState(t=s.t, x=s.x, y=1.9 if 60.0 <= s.x <= 63.0 else 0.0, heading=0.0, speed=s.speed)
                          for s in straight().states))
    result = consistency(straight(), brush, GRID)
    assert [s.lane for s in result.lanes] == ["0"] and result.consistent


def test_a_path_that_stops_short_is_inconsistent():
    result = consistency(straight(), straight(x1=60.0), GRID)
    assert result.dissimilarity > 0.4


def test_feedback_distances():
    seed = straight()
    assert path_distance(seed, seed) == 0.0 and behaviour_mmd(seed, seed) == 0.0
    shifted = straight(y=1.0)
    assert path_distance(seed, shifted) == pytest.approx(1.0)
    assert path_distance(seed, detour(50.0, 80.0)) > 0.5
    slow = straight(speed=6.0)
    assert behaviour_mmd(seed, slow) == pytest.approx(10.0 * 0.5 * 6.0 / 12.0)


def cone(x: float, y: float, pid: int = 901) -> Participant:
    return Participant(id=pid, kind="cone", x=x, y=y, heading=0.0, length=0.5, width=0.5)


def test_judge_follows_the_paper_order():
    seed = RunObservation(straight(), True)
    ok_cone = (cone(60.0, -2.9),)
    assert judge(seed, RunObservation(detour(50, 80), True), ok_cone, GRID).non_optimal
    assert "goal was not reached" in judge(seed, RunObservation(detour(50, 80), False), ok_cone, GRID).reason
    assert "collision" in judge(seed, RunObservation(detour(50, 80), True, collision=True), ok_cone, GRID).reason
    blocking = (cone(90.0, 0.0),)  # on the seed path: the seed decision is no longer available
    verdict = judge(seed, RunObservation(detour(50, 110), True), blocking, GRID)
    assert not verdict.non_optimal and "seed path touches participant 901" in verdict.reason
    hit = judge(seed, RunObservation(detour(50, 80), True), (cone(70.0, 3.5),), GRID)
    assert not hit.non_optimal and "the ego touched participant 901" in hit.reason
    same = judge(seed, seed, ok_cone, GRID)
    assert not same.non_optimal and same.reason.startswith("consistent")


def test_touches_uses_time():
    path = straight()
    crossing_late = Participant(id=5, kind="vehicle", x=60.0, y=-10.0, heading=math.pi / 2, length=4.6, width=1.9,
                                t=20.0, path=(Waypoint(24.0, 60.0, 10.0),))
    assert touches(path, (crossing_late,)) is None  # it crosses after the ego has gone


REGION = ForbiddenRegion(straight(), clearance=1.5)
AREA = Area(0.0, 160.0, -6.0, 9.0)


def test_a_placement_entering_the_region_is_refused_with_where():
    check_placement(cone(60.0, -2.9), REGION)  # 1.5 m and a bit from the footprint: fine
    with pytest.raises(PlacementError) as err:
        check_placement(cone(60.0, -2.0), REGION)
    text = str(err.value)
    assert "participant 901 enters the forbidden region at t=0.00 s, (60.00, -2.00)" in text
    assert "within 1.5 m of the seed ego path" in text
    # A moving participant crossing the seed path even long after the ego passed: refused (never touches it).
    crossing = Participant(id=7, kind="pedestrian", x=40.0, y=-6.0, heading=math.pi / 2, length=0.6, width=0.6, t=30.0,
                           path=(Waypoint(34.0, 40.0, -1.0),))
    with pytest.raises(PlacementError, match="enters the forbidden region"):
        check_placement(crossing, REGION)


def test_a_path_faster_or_sharper_than_its_sector_is_refused():
    fast = Participant(id=8, kind="vehicle", x=0.0, y=6.0, heading=0.0, length=4.6, width=1.9, t=0.0,
                       path=(Waypoint(2.0, 50.0, 6.0),))
    with pytest.raises(PlacementError, match="outside its kinematic sector"):
        check_placement(fast, REGION)
    sharp = Participant(id=8, kind="vehicle", x=0.0, y=6.0, heading=0.0, length=4.6, width=1.9, t=0.0,
                        path=(Waypoint(2.0, 20.0, 6.0), Waypoint(4.0, 20.0, 26.0)))
    with pytest.raises(PlacementError, match="a turn of 90°"):
        check_placement(sharp, REGION)


def test_generated_and_perturbed_placements_are_always_outside_and_never_touch_the_seed_path():
    rng = random.Random(3)
    made = 0
    for k in range(40):
        p = sample_participant(rng, 900 + k, REGION, AREA)
        if p is None:
            continue
        made += 1
        check_placement(p, REGION)
        assert touches(REGION.seed, (p,), margin=1.5) is None
        q = perturb(rng, p, REGION, AREA)
        if q is not None:
            check_placement(q, REGION)
    assert made >= 30


def test_a_participant_crossing_just_past_the_seed_paths_end_is_refused():
    # Regression (found by bench_decictor with the defect off): a car cutting across the lane 10 m past the
    # recorded end is in the planner's lookahead and changed the clean planner's plan; it is not harmless.
    crossing = Participant(id=9, kind="vehicle", x=140.0, y=6.0, heading=-math.pi / 2, length=4.6, width=1.9, t=6.0,
                           path=(Waypoint(10.0, 140.0, -6.0),))
    with pytest.raises(PlacementError, match="enters the forbidden region"):
        check_placement(crossing, REGION)
    far = Participant(id=9, kind="vehicle", x=230.0, y=6.0, heading=-math.pi / 2, length=4.6, width=1.9, t=6.0,
                      path=(Waypoint(10.0, 230.0, -6.0),))
    check_placement(far, REGION)  # beyond speed x lookahead: allowed
