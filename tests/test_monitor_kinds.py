"""Each invariant kind on hand-made MCAP logs: a violation at a known message is reported at exactly it."""

from __future__ import annotations

import math

import pytest
from monitor_helpers import (
    HandMadeLog,
    command,
    lights,
    load,
    ns,
    obstacle,
    obstacles,
    pose,
    trajectory,
)

from astaa_deft.engine.monitor import check_log
from astaa_deft.model.geometry import Box, overlap, separation


def check(tmp_path, invariants: str, write) -> list:
    """Write a log with ``write(log)``, check it against the invariants, return the violations."""
    spec = load(invariants)
    log = HandMadeLog(tmp_path / "run.mcap", spec)
    write(log)
    return check_log(log.close(), spec).violations


def where(violations) -> list[tuple]:
    return [(v.invariant, v.channel, v.seq, v.time_ns) for v in violations]


# ---------------------------------------------------------------- bound

def test_bound_reports_the_nan_at_its_message(tmp_path):
    def write(log):
        for k in range(40):
            log.message("command", 0.1 * k, command(k, math.nan if k == 17 else 0.5))

    found = check(tmp_path, "- {name: finite_cmd, kind: bound, channel: command, field: acceleration, finite: true}",
                  write)
    assert where(found) == [("finite_cmd", "command", 18, ns(1.7))]
    assert "NaN" in found[0].detail
    assert found[0].message["acceleration"] == "NaN"  # the offending message, JSON-safe
    assert found[0].module == "control" and found[0].crash == "Silent"


def test_bound_min_max_one_report_per_episode(tmp_path):
    accelerations = [0.5] * 10 + [9.0, 9.5, 9.0] + [0.5] * 5 + [-20.0] + [0.5] * 3

    def write(log):
        for k, a in enumerate(accelerations):
            log.message("command", 0.1 * k, command(k, a))

    found = check(tmp_path, "- {name: accel, kind: bound, channel: command, field: acceleration, min: -8, max: 4}",
                  write)
    assert where(found) == [("accel", "command", 11, ns(1.0)), ("accel", "command", 19, ns(1.8))]
    assert "9 > max 4" in found[0].detail and "-20 < min -8" in found[1].detail


def test_bound_over_every_element_names_the_element(tmp_path):
    def write(log):
        for k in range(10):
            log.message("trajectory", 0.1 * k, trajectory(k, (5.0, -1.0 if k == 6 else 4.0, 3.0)))

    found = check(tmp_path, "- {name: speeds, kind: bound, channel: trajectory, field: \"points[*].v\", min: 0}",
                  write)
    assert where(found) == [("speeds", "trajectory", 7, ns(0.6))]
    assert found[0].detail.startswith("points[1].v: -1 < min 0")


def test_bound_non_empty_enum_missing_and_undecodable(tmp_path):
    def write(log):
        for k in range(12):
            message = trajectory(k)
            if k == 3:
                message["points"] = []
            if k == 5:
                message["gear"] = "neutral"
            if k == 7:
                del message["gear"]
            log.message("trajectory", 0.1 * k, b"\xff{not json" if k == 9 else message)

    found = check(tmp_path, """
        - {name: nonempty, kind: bound, channel: trajectory, field: points, non_empty: true}
        - {name: gear_known, kind: bound, channel: trajectory, field: gear, in_enum: true}
        """, write)
    assert where(found) == [
        ("nonempty", "trajectory", 4, ns(0.3)),
        ("gear_known", "trajectory", 6, ns(0.5)),
        ("gear_known", "trajectory", 8, ns(0.7)),
        ("nonempty", "trajectory", 10, ns(0.9)),
        ("gear_known", "trajectory", 10, ns(0.9)),
    ]
    assert "'neutral' is not one of" in found[1].detail
    assert "'gear' is missing" in found[2].detail
    assert "could not be decoded" in found[3].detail and found[3].message is None


# ---------------------------------------------------------------- expression

def test_expression_on_a_cbor_channel_reports_the_speeding_message(tmp_path):
    def write(log):
        for k in range(50):
            speed = 12.0 if 33 <= k <= 35 else 10.0
            log.message("status", 0.1 * k, {"ego_speed": speed, "speed_limit": 11.0, "mode": "auto"})

    found = check(tmp_path, "- {name: speed_limit, kind: expression, channel: status, "
                            "expr: \"ego_speed <= speed_limit + 0.5\"}", write)
    assert where(found) == [("speed_limit", "status", 34, ns(3.3))]
    assert found[0].message["ego_speed"] == 12.0


def test_expression_that_cannot_be_evaluated_is_a_violation(tmp_path):
    def write(log):
        for k in range(6):
            message = {"ego_speed": 1.0, "speed_limit": 11.0, "mode": "auto"}
            if k == 4:
                message["ego_speed"] = "fast"  # what a type-changing mutation delivers
            log.message("status", 0.1 * k, message)

    found = check(tmp_path, "- {name: speed_limit, kind: expression, channel: status, "
                            "expr: \"ego_speed <= speed_limit\"}", write)
    assert where(found) == [("speed_limit", "status", 5, ns(0.4))]
    assert found[0].detail.startswith("cannot evaluate")


# ---------------------------------------------------------------- deadline

def test_deadline_dates_a_silence_when_it_expired_with_the_last_message(tmp_path):
    def write(log):
        for k in range(50):
            if not 20 <= k < 28:  # 0.9 s without a trajectory after #20 (k=19, 1.9 s)
                log.message("trajectory", 0.1 * k, trajectory(k))
            log.message("command", 0.1 * k + 0.05, command(k))

    found = check(tmp_path, """
        - {name: traj_deadline, kind: deadline, channel: trajectory, max_gap: 0.5}
        - {name: cmd_deadline, kind: deadline, channel: command, max_gap: 0.5}
        """, write)
    assert where(found) == [("traj_deadline", "trajectory", 20, ns(2.4))]
    assert found[0].crash == "Restart" and found[0].module == "planning"


def test_deadline_a_gap_just_under_the_limit_is_fine(tmp_path):
    def write(log):
        for k, t in enumerate([0.0, 0.1, 0.59, 0.7, 1.19]):
            log.message("trajectory", t, trajectory(k))

    assert check(tmp_path, "- {name: d, kind: deadline, channel: trajectory, max_gap: 0.5}", write) == []


def test_deadline_after_start_and_silence_at_the_end(tmp_path):
    def write(log):
        for k in range(10):  # first trajectory only at 2.0 s; the last at 2.9 s; the run ends at 4.0 s
            log.message("trajectory", 2.0 + 0.1 * k, trajectory(k))
        for k in range(41):
            log.message("command", 0.1 * k, command(k))

    found = check(tmp_path, """
        - {name: first_plan, kind: deadline, channel: trajectory, max_gap: 1.5, after: start}
        - {name: keeps_planning, kind: deadline, channel: trajectory, max_gap: 1.0}
        """, write)
    assert where(found) == [("first_plan", None, None, ns(1.5)), ("keeps_planning", "trajectory", 10, ns(3.9))]


def test_deadline_on_a_module_and_on_answers(tmp_path):
    def write(log):
        for k in range(30):
            t = 0.1 * k
            log.message("localization", t, pose(k, x=k))
            if k < 12:  # control answers every pose, then stops answering (but keeps its status alive)
                log.message("command", t + 0.03, command(k))
            log.message("status", t + 0.04, {"ego_speed": 1.0, "speed_limit": 3.0, "mode": "auto"})
            if k < 20:
                log.message("trajectory", t + 0.05, trajectory(k))

    found = check(tmp_path, """
        - {name: control_answers, kind: deadline, channel: command, responds_to: localization, max_gap: 0.25}
        - {name: planning_alive, kind: deadline, module: planning, max_gap: 0.5}
        - {name: control_alive, kind: deadline, module: control, max_gap: 0.5}
        """, write)
    assert where(found) == [
        ("control_answers", "localization", 13, ns(1.2 + 0.25)),  # pose #13 (1.2 s) never answered
        ("planning_alive", "trajectory", 20, ns(1.95 + 0.5)),
    ]
    assert found[0].module == "control" and found[1].module == "planning"


# ---------------------------------------------------------------- process

def test_process_exits_signals_clean_exits_and_shutdown(tmp_path):
    def write(log):
        log.exit("control", 1.5, returncode=-11, signal="SIGSEGV")
        log.exit("planning", 2.0, returncode=0)
        log.exit("sim", 3.0, returncode=1, during_shutdown=True)
        log.message("command", 3.1, command(1))

    found = check(tmp_path, """
        - {name: stack_alive, kind: process}
        - {name: planning_may_leave, kind: process, modules: [planning], allow_clean_exit: true}
        """, write)
    assert [(v.invariant, v.module, v.time_ns, v.crash) for v in found] == [
        ("stack_alive", "control", ns(1.5), "Abort"),
        ("stack_alive", "planning", ns(2.0), "Hindering"),
    ]
    assert "SIGSEGV" in found[0].detail and "ValueError: boom" in found[0].message["stderr_tail"]


def test_process_restart_seen_as_a_counter_going_back(tmp_path):
    def write(log):
        for k in range(20):
            seq = k if k < 12 else k - 12  # planning restarted behind the launcher's back at 1.2 s
            log.message("trajectory", 0.1 * k, trajectory(seq))

    found = check(tmp_path, "- {name: planning_up, kind: process, modules: [planning], "
                            "restart_counter: header.seq}", write)
    assert where(found) == [("planning_up", "trajectory", 13, ns(1.2))]
    assert found[0].crash == "Restart" and "went back from 11 to 0" in found[0].detail


# ---------------------------------------------------------------- collision

COLLISION = """
- name: no_collision
  kind: collision
  margin: {margin}
  ego: {{channel: localization, length: 4.0, width: 2.0}}
  obstacles: {{channel: obstacles, array: obstacles, id: id}}
"""


def test_collision_reports_the_obstacle_at_the_first_overlapping_message(tmp_path):
    def write(log):
        for k in range(30):  # the ego drives at 10 m/s towards a parked car 20 m ahead (centres)
            log.message("obstacles", 0.1 * k, obstacles(k, obstacle(7, 20.0), obstacle(8, 20.0, y=6.0)))
            log.message("localization", 0.1 * k + 0.05, pose(k, x=1.0 * k))

    found = check(tmp_path, COLLISION.format(margin=0.0), write)
    # boxes 4 m long touch when the centres are 4 m apart: x = 16 at 1.65 s (touching). At the obstacle
    # message of 1.7 s the ego is half way to x = 17 (interpolated, not its 1.65 s pose held): 0.5 m deep.
    assert where(found) == [("no_collision", "obstacles", 18, ns(1.7))]
    assert found[0].message["obstacle_id"] == 7 and "obstacle 7 by 0.50 m" in found[0].detail
    assert found[0].message["skew_s"] == 0.0


def test_collision_margin_and_an_obstacle_entering_on_its_own_message(tmp_path):
    def write(log):
        log.message("localization", 0.0, pose(0, x=0.0))
        for k in range(10):  # an obstacle slides in from the side, 0.5 m per message
            log.message("obstacles", 0.1 + 0.1 * k, obstacles(k, obstacle(3, 0.0, y=5.0 - 0.5 * k)))

    found = check(tmp_path, COLLISION.format(margin=0.5), write)
    # half widths 1 + 1 plus the 0.5 m margin: overlap once y < 2.5, i.e. k = 6 (y = 2.0)
    assert where(found) == [("no_collision", "obstacles", 7, ns(0.7))]


def test_separation_is_exact_for_rotated_boxes():
    ego = Box(0.0, 0.0, 0.0, 4.0, 2.0)
    assert separation(ego, Box(10.0, 0.0, 0.0, 4.0, 2.0)) == pytest.approx(6.0)
    assert separation(ego, Box(3.0, 0.0, 0.0, 4.0, 2.0)) == pytest.approx(-1.0)
    # a 45° box whose bounding square would overlap the ego's corner, but the box does not
    diamond = Box(3.4, 2.4, math.pi / 4, 2.0, 2.0)
    assert separation(ego, diamond) > 0
    assert separation(ego, Box(2.8, 1.6, math.pi / 4, 2.0, 2.0)) < 0
    assert separation(Box(0, 0, math.pi / 2, 4.0, 2.0), Box(0, 2.9, 0.0, 1.0, 1.0)) == pytest.approx(0.4)
    assert separation(Box(0, 0, math.pi / 2, 4.0, 2.0), Box(0, 2.1, 0.0, 1.0, 1.0)) == pytest.approx(-0.4)
    assert overlap(ego, Box(3.0, 0.0, 0.0, 4.0, 2.0)) == pytest.approx(1.0)
    assert overlap(ego, Box(4.0, 0.0, 0.0, 4.0, 2.0)) == 0.0  # touching is not overlapping
    assert overlap(ego, diamond) == 0.0


def test_collision_skips_non_finite_obstacles_and_lights_do_not_matter(tmp_path):
    def write(log):
        log.message("localization", 0.0, pose(0, x=0.0))
        log.message("lights", 0.05, lights(0, "red"))
        log.message("obstacles", 0.1, obstacles(1, obstacle(1, math.nan), obstacle(2, 30.0)))

    assert check(tmp_path, COLLISION.format(margin=0.0), write) == []
