"""The demo's seeded decision defect (5), judged by Decictor's oracle in the deterministic closed loop:
a harmless cone on the shoulder flips the defective planner into a needless lane change; the clean
planner keeps the seed's path; a placement on the seed path is refused before it runs. The closed-loop
runner joining the tool to the demo lives in benchmarks/ (the tool never imports the demo)."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from astaa_deft.analysis.decictor.feasible import ForbiddenRegion, PlacementError, check_placement
from astaa_deft.analysis.decictor.oracle import LaneGrid, judge, straight_lanes
from astaa_deft.engine.intercept.actions.participant import Participant, read_mappings
from astaa_deft.engine.spec.loader import load_spec

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))
from decictor_loop import observe_closed_loop  # noqa: E402 - the benchmarks' closed loop, found on the path above

SPEC = load_spec(Path(__file__).resolve().parent.parent / "specs" / "demo_av.yaml")
MAPPING = read_mappings(SPEC)["prediction"]
GRID = LaneGrid(straight_lanes(2, 3.5, 300.0))
CONE = Participant(id=901, kind="cone", x=60.0, y=-3.0, heading=0.0, length=0.5, width=0.5)


@pytest.fixture(scope="module")
def seed():
    return observe_closed_loop("lane_follow", (), MAPPING, defects=True)


def test_the_seed_reaches_its_goal_in_its_lane(seed):
    assert seed.goal_reached and not seed.collision
    assert max(abs(s.y) for s in seed.ego.states) < 0.2


@pytest.mark.parametrize("defects", [True, False])
def test_a_cone_on_the_shoulder_is_a_non_optimal_decision_only_with_the_defect(seed, defects):
    check_placement(CONE, ForbiddenRegion(seed.ego, clearance=SPEC.decictor.clearance))  # harmless
    mutated = observe_closed_loop("lane_follow", (CONE,), MAPPING, defects=defects)
    verdict = judge(seed, mutated, (CONE,), GRID)
    if defects:
        assert verdict.non_optimal, verdict.reason
        assert verdict.consistency.worst_lane == "1" and max(s.y for s in mutated.ego.states) > 3.0
    else:
        assert not verdict.non_optimal and verdict.consistency.dissimilarity == 0.0
        assert verdict.path_distance < 0.05


def test_a_cone_on_the_seed_path_is_refused(seed):
    with pytest.raises(PlacementError, match="enters the forbidden region"):
        check_placement(Participant(id=902, kind="cone", x=60.0, y=-1.5, heading=0.0, length=0.5, width=0.5),
                        ForbiddenRegion(seed.ego, clearance=SPEC.decictor.clearance))


def test_a_turned_cone_or_a_barrier_on_the_shoulder_closes_the_lane_too(seed):
    # Regression: the defect widened a cone along its own width axis, so a cone turned ~1 rad (as the
    # search places them: any heading) widened along the road and changed nothing; the search sat on
    # such cones for whole budgets. Furniture on the shoulder now widens across the road, however turned.
    for participant in (Participant(id=901, kind="cone", x=60.0, y=-3.0, heading=1.0, length=0.5, width=0.5),
                        Participant(id=901, kind="barrier", x=60.0, y=-3.6, heading=2.0, length=0.6, width=2.0)):
        mutated = observe_closed_loop("lane_follow", (participant,), MAPPING, defects=True)
        verdict = judge(seed, mutated, (participant,), GRID)
        assert verdict.non_optimal, (participant, verdict.reason)


def test_furniture_further_out_slows_the_ego_less_a_gradient_the_search_climbs(seed):
    fitness = []
    for y in (-4.2, -5.2):
        cone = Participant(id=901, kind="cone", x=70.0, y=y, heading=0.0, length=0.5, width=0.5)
        verdict = judge(seed, observe_closed_loop("lane_follow", (cone,), MAPPING, defects=True), (cone,), GRID)
        assert not verdict.non_optimal, verdict.reason  # it keeps its lane: only slower beside the cone
        fitness.append(verdict.fitness)
    assert fitness[0] > fitness[1] > 0.0
