"""The demo planner as DeFT uses it: a pure function of (frames so far), and a sensible one.

Frames come from the in-process closed loop (astaa_deft.demo.closed_loop):
the real world, prediction, planner and controller, each message a JSON
round trip, so they look exactly like frames rebuilt from a recording.
"""

from __future__ import annotations

import copy
import json
import math

import pytest

from astaa_deft.demo import vehicle
from astaa_deft.demo.closed_loop import run_closed_loop
from astaa_deft.demo.geometry import Box, boxes_overlap
from astaa_deft.demo.messages import PerceivedObstacle
from astaa_deft.demo.planner_core import Planner
from astaa_deft.demo.prediction import predict

LANE_WIDTH = 3.5


@pytest.fixture(scope="module")
def cut_in_run():
    return run_closed_loop("cut_in")


def replay(frames, defects=False) -> list[bytes]:
    planner = Planner(defects=defects)
    return [json.dumps(planner.step(frame)).encode() for frame in frames]


def test_replaying_recorded_frames_is_bit_identical(cut_in_run):
    first, second = replay(cut_in_run.frames), replay(cut_in_run.frames)
    assert len(first) == len(cut_in_run.frames) > 100
    assert first == second
    # …and identical to what the planner published during the run itself.
    assert first == [json.dumps(t).encode() for t in cut_in_run.trajectories]


def test_output_does_not_depend_on_how_the_frame_dict_was_built(cut_in_run):
    reordered = [dict(reversed(list(frame.items()))) for frame in cut_in_run.frames]
    assert replay(reordered) == replay(cut_in_run.frames)


def test_step_leaves_its_inputs_untouched(cut_in_run):
    frames = cut_in_run.frames[:30]
    before = copy.deepcopy(frames)
    replay(frames)
    assert frames == before


def test_frames_must_be_replayed_in_order_because_the_planner_keeps_state(cut_in_run):
    # DeFT replays from the first frame: a planner started midway decides differently.
    middle = len(cut_in_run.frames) // 2
    full = replay(cut_in_run.frames)[middle:]
    cold = replay(cut_in_run.frames[middle:])
    assert full != cold


def test_debug_names_the_sequence_numbers_of_the_inputs_used(cut_in_run):
    for frame, trajectory in zip(cut_in_run.frames, cut_in_run.trajectories):
        assert trajectory["debug"]["inputs"] == {name: msg["header"]["seq"] for name, msg in frame.items()}
        assert trajectory["header"]["stamp"] == frame["prediction"]["header"]["stamp"]
    seqs = [t["header"]["seq"] for t in cut_in_run.trajectories]
    assert seqs == list(range(1, len(seqs) + 1))


def test_trajectory_times_are_absolute_sim_time(cut_in_run):
    trajectory = cut_in_run.trajectories[40]
    now = trajectory["header"]["stamp"]
    times = [p["t"] for p in trajectory["points"]]
    assert times[0] == pytest.approx(now) and times[-1] == pytest.approx(now + 5.0)
    assert all(b > a for a, b in zip(times, times[1:]))


@pytest.mark.parametrize("scenario", ["lane_follow", "static_obstacle", "cut_in", "red_light"])
def test_scenarios_reach_the_goal_without_collision(scenario):
    status = run_closed_loop(scenario).status
    assert status["goal_reached"] and not status["collision"], status
    assert status["min_clearance"] > 0.3
    assert 8.0 <= status["goal_time"] <= 15.0


# --- single frames ------------------------------------------------------------

def frame(*, x=20.0, y=0.0, speed=10.0, obstacles=(), lights=(), limit=13.0, lanes=2, stamp=1.0) -> dict:
    """A hand-made frame: the ego at (x, y) heading along the road, static obstacles, lights."""
    header = {"seq": 1, "stamp": stamp}
    perceived = [
        PerceivedObstacle(id=i + 1, kind=kind, x=ox, y=oy, heading=0.0, vx=0.0, vy=0.0, length=length, width=width)
        for i, (kind, ox, oy, length, width) in enumerate(obstacles)
    ]
    return {
        "routing": {"header": header, "lane_count": lanes, "lane_width": LANE_WIDTH, "road_length": 300.0,
                    "goal": {"x": 250.0, "lane": 0}, "speed_limit": limit},
        "localization": {"header": header, "x": x, "y": y, "heading": 0.0, "speed": speed,
                         "acceleration": 0.0, "yaw_rate": 0.0},
        "traffic_light": {"header": header, "lights": [
            {"id": i + 1, "state": state, "stop_line_x": line} for i, (state, line) in enumerate(lights)]},
        "prediction": {"header": header, "obstacles": [predict(stamp, o) for o in perceived]},
    }


def front(point: dict) -> float:
    return point["x"] + 0.5 * vehicle.LENGTH


def hits(points: list[dict], obstacle: tuple) -> bool:
    _, ox, oy, length, width = obstacle
    target = Box(ox, oy, 0.0, length, width)
    return any(boxes_overlap(Box(p["x"], p["y"], p["heading"], vehicle.LENGTH, vehicle.WIDTH), target)
               for p in points)


def test_red_light_plans_a_stop_before_the_line():
    planned = Planner().step(frame(x=30.0, speed=10.0, lights=[("red", 50.0)]))
    points = planned["points"]
    assert planned["decision"]["behavior"] == "stop"
    assert max(front(p) for p in points) <= 50.0
    assert points[-1]["v"] == 0.0


def test_green_light_is_driven_through():
    points = Planner().step(frame(x=30.0, speed=10.0, lights=[("green", 50.0)]))["points"]
    assert max(front(p) for p in points) > 60.0


def test_red_light_closed_loop_waits_then_goes():
    run = run_closed_loop("red_light")
    red_until, line = 7.0, 50.0
    while_red = [f["localization"] for f in run.frames if f["localization"]["header"]["stamp"] < red_until]
    assert max(loc["x"] + 0.5 * vehicle.LENGTH for loc in while_red) < line
    assert min(loc["speed"] for loc in while_red) < 0.05  # it really stood still
    assert run.status["goal_reached"]


def test_blocked_lane_is_avoided_by_changing_lane():
    stalled = ("vehicle", 55.0, 0.0, 4.6, 1.9)
    planned = Planner().step(frame(x=20.0, speed=10.0, obstacles=[stalled]))
    assert planned["decision"] == {"lane": 1, "behavior": "lane_change"}
    assert not hits(planned["points"], stalled)
    assert planned["points"][-1]["y"] == pytest.approx(LANE_WIDTH, abs=0.05)


def test_road_blocked_in_every_lane_stops_short_of_it():
    barrier = ("barrier", 50.0, 0.5 * LANE_WIDTH, 1.0, 2 * LANE_WIDTH + 1.0)
    planned = Planner().step(frame(x=30.0, speed=10.0, obstacles=[barrier]))
    assert not hits(planned["points"], barrier)
    assert planned["points"][-1]["v"] == 0.0
    assert max(front(p) for p in planned["points"]) < 50.0 - 0.5


def test_a_started_lane_change_is_continued_not_replanned():
    # Re-planning the lane change from scratch every cycle would push its end ahead for ever;
    # the planner keeps the committed path, so a later plan lies on the earlier one.
    stalled = [("vehicle", 55.0, 0.0, 4.6, 1.9)]
    planner = Planner()
    first = planner.step(frame(x=20.0, speed=10.0, obstacles=stalled))["points"]
    on_plan = first[10]  # where the first plan put the ego one second later
    later = frame(x=on_plan["x"], y=on_plan["y"], speed=on_plan["v"], obstacles=stalled, stamp=2.0)
    later["localization"]["heading"] = on_plan["heading"]
    second = planner.step(later)["points"]
    fresh = Planner().step(later)["points"]

    def y_on_first(x):
        return next(p["y"] for p in first if p["x"] >= x)

    overlap = [p for p in second if p["x"] <= first[-1]["x"]]
    assert max(abs(p["y"] - y_on_first(p["x"])) for p in overlap) < 0.1
    assert max(abs(p["y"] - y_on_first(p["x"])) for p in fresh if p["x"] <= first[-1]["x"]) > 0.1


def test_speed_limit_is_respected():
    points = Planner().step(frame(speed=12.0, limit=13.0))["points"]
    assert max(p["v"] for p in points) <= 13.0
    assert points[-1]["v"] > 12.0


@pytest.mark.parametrize("defects, overspeed", [(True, True), (False, False)])
def test_nan_speed_limit_defect_in_the_planner_core(defects, overspeed):
    planner = Planner(defects=defects)
    planner.step(frame(speed=12.0, limit=13.0))
    points = planner.step(frame(speed=12.0, limit=math.nan, stamp=1.1))["points"]
    assert (max(p["v"] for p in points) > 15.0) == overspeed
