"""The demo's seeded decision defect (5), judged by Decictor's oracle in the deterministic closed loop:
a harmless cone on the shoulder flips the defective planner into a needless lane change; the clean
planner keeps the seed's path; a placement on the seed path is refused before it runs."""

from __future__ import annotations

from pathlib import Path

import pytest

from astaa_deft.decictor.closed_loop import observe_closed_loop
from astaa_deft.decictor.feasible import ForbiddenRegion, PlacementError, check_placement
from astaa_deft.decictor.oracle import LaneGrid, judge, straight_lanes
from astaa_deft.intercept.actions.participant import Participant, read_mappings
from astaa_deft.spec_loader import load_spec

SPEC = load_spec(Path(__file__).resolve().parent.parent / "specs" / "demo_av.yaml")
MAPPING = read_mappings(SPEC)["prediction"]
GRID = LaneGrid(straight_lanes(2, 3.5, 300.0))
CONE = Participant(901, "cone", 60.0, -3.0, 0.0, 0.5, 0.5)


@pytest.fixture(scope="module")
def seed():
    return observe_closed_loop("lane_follow", (), MAPPING, defects=True)


def test_the_seed_reaches_its_goal_in_its_lane(seed):
    assert seed.goal_reached and not seed.collision
    assert max(abs(s.y) for s in seed.ego.states) < 0.2


@pytest.mark.parametrize("defects", [True, False])
def test_a_cone_on_the_shoulder_is_a_non_optimal_decision_only_with_the_defect(seed, defects):
    check_placement(CONE, ForbiddenRegion(seed.ego, clearance=SPEC.decictor["clearance"]))  # harmless
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
        check_placement(Participant(902, "cone", 60.0, -1.5, 0.0, 0.5, 0.5),
                        ForbiddenRegion(seed.ego, clearance=SPEC.decictor["clearance"]))
