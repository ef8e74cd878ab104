"""A non-optimal decision as a deterministic module test: DeFT frames + a path-consistency oracle.

``write_consistency_test(suite_dir, seed_plans, lanes)`` adds to an exported
DeFT suite (the frames of the mutated run) the seed run's planned paths and
a pytest file. The test replays the frames in order through the planner and
compares where each replayed plan leads — its end point, the decision's
destination — with where the seed run's plans led, on the lane grid of the
oracle: 1 - Jaccard > 0.4 on the worst lane fails. With the planner's defect
the replayed plans head for the other lane as in the run and the test fails;
without it they keep to the seed's lane and it passes. The params the run
was recorded with can be overridden: ``DECICTOR_PARAMS=defects=off pytest DIR``.
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from pathlib import Path

from astaa_deft.io.output_place import write_atomic
from astaa_deft.model.replay_module import TrajectoryLayout
from astaa_deft.analysis.deft.planner_section import planner_of
from astaa_deft.analysis.deft.replay import trajectory_points
from astaa_deft.analysis.deft.suite import Suite
from astaa_deft.analysis.decictor.oracle import Consistency, Lane, LaneGrid, consistency
from astaa_deft.analysis.decictor.paths import EgoPath, EgoState

SEED_FILE = "decictor_seed.json"
TEST_FILE = "test_decictor_consistency.py"
PARAMS_VARIABLE = "DECICTOR_PARAMS"

TEST_TEXT = '''\
"""Written by astaa-deft fuzz --strategy decictor: the replayed plans must keep to the seed run's lanes.

Override the recorded params with e.g. DECICTOR_PARAMS=defects=off (comma-separated key=value).
"""

from pathlib import Path

from astaa_deft.analysis.decictor.module_test import check_suite


def test_replayed_plans_keep_the_seed_runs_path():
    problem = check_suite(Path(__file__).resolve().parent)
    assert problem is None, problem
'''


def end_points(messages: Sequence[object], layout: TrajectoryLayout | None) -> list[tuple[float, float]]:
    """Where each plan ends (x, y), in order; a plan without points has none (as has a planner without a layout)."""
    out: list[tuple[float, float]] = []
    if layout is None:
        return out
    for message in messages:
        points = trajectory_points(message, layout)
        if points:
            out.append((float(points[-1][0]), float(points[-1][1])))
    return out


def as_path(points: list[tuple[float, float]]) -> EgoPath:
    # Ordered by station, as a planned path is: the end points of successive plans advance along the road.
    return EgoPath(tuple(EgoState(t=float(k), x=x, y=y, heading=0.0) for k, (x, y) in enumerate(points)))


def write_consistency_test(suite_dir: Path, seed_plans: list[tuple[float, float]], lanes: tuple[Lane, ...],
                           note: str = "") -> None:
    body = {"seed_plan_ends": seed_plans, "note": note,
            "lanes": [{"id": lane.id, "width": lane.width, "centre": list(lane.centre)} for lane in lanes]}
    write_atomic(suite_dir / SEED_FILE, json.dumps(body, indent=1) + "\n")  # whole, never through a link
    write_atomic(suite_dir / TEST_FILE, TEST_TEXT)


def replay_consistency(suite_dir: Path, overrides: str | None = None) -> Consistency:
    seed = json.loads((suite_dir / SEED_FILE).read_text())
    lanes = tuple(Lane(str(lane["id"]), tuple((float(x), float(y)) for x, y in lane["centre"]),
                       float(lane["width"])) for lane in seed["lanes"])
    suite = Suite(suite_dir)
    text = os.environ.get(PARAMS_VARIABLE, "") if overrides is None else overrides
    for item in filter(None, (part.strip() for part in text.split(","))):
        key, _, value = item.partition("=")
        suite.manifest["params"][key.strip()] = value.strip()
    replayed = end_points([r.message for r in suite.results()], planner_of(suite.spec).trajectory)
    seed_path = as_path([(float(x), float(y)) for x, y in seed["seed_plan_ends"]])
    return consistency(seed_path, as_path(replayed), LaneGrid(lanes))


def check_suite(suite_dir: Path, overrides: str | None = None) -> str | None:
    """None if the replayed plans keep to the seed's lanes; else what differs."""
    result = replay_consistency(suite_dir, overrides)
    if result.consistent:
        return None
    lanes = ", ".join(f"lane {s.lane}: Jaccard {s.jaccard:.2f} (seed {s.seed_cells} cells, replay "
                      f"{s.mutated_cells})" for s in result.lanes)
    return (f"the replayed plans leave the seed run's path: worst lane {result.worst_lane}, 1 - Jaccard "
            f"{result.dissimilarity:.2f} > 0.4 ({lanes})")
