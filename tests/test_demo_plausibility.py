"""Inputs no car or road of the demo has: with defects off, the demo modules ignore them.

Each was found by a campaign with the defects off (benchmarks/bench_campaign.py's
false alarms): not seeded defects, but real gaps of the demo stack that made
a clean stack fail under one mutated message. The modules' own logic, run
in-process (the planner's and the controller's pure classes).
"""

from __future__ import annotations

import math

from astaa_deft.demo.control import Controller
from astaa_deft.demo.messages import Localization
from astaa_deft.demo.planner_core import Planner

from test_demo_planner import frame

def test_a_speed_limit_beyond_the_odd_is_ignored_with_defects_off():
    """routing.speed_limit = 3.4e38 (a campaign's max_float32) once: the last good limit still applies."""
    planner = Planner(defects=False)
    planner.step(frame(limit=13.0, stamp=1.0))
    corrupted = planner.step(frame(limit=3.4028234663852886e38, stamp=1.1))
    assert max(p["v"] for p in corrupted["points"]) <= 13.0


def _command_after(controller: Controller, loc_speed: float, plan_v: float = 10.0) -> list[dict]:
    points = [{"t": 1.0 + 0.1 * k, "x": 10.0 * (1.0 + 0.1 * k), "y": 0.0, "heading": 0.0, "v": 10.0, "a": 0.0}
              for k in range(51)]
    controller.on_trajectory({"header": {"seq": 1, "stamp": 1.0}, "points": points})
    corrupted = [dict(p, v=plan_v) for p in points]
    controller.on_trajectory({"header": {"seq": 2, "stamp": 1.0}, "points": corrupted})
    commands = []
    for k in range(20):
        stamp = 1.0 + 0.02 * k
        speed = loc_speed if k == 5 else 10.0
        commands.append(controller.on_localization(Localization(stamp, 10.0 * stamp, 0.0, 0.0, speed, 0.0, 0.0)))
    return [c for c in commands if c is not None]


def test_an_overflowing_measured_speed_leaves_control_finite_with_defects_off():
    """localization.speed = 1.8e308 once: its error minus the next one overflows, and the PID's filtered
    derivative would stay NaN for good; with defects off control ignores such a measurement."""
    commands = _command_after(Controller(defects=False), loc_speed=1.7976931348623157e308)
    assert len(commands) == 20 and all(math.isfinite(c["acceleration"]) for c in commands)


def test_a_plan_speed_no_car_reaches_is_ignored_with_defects_off():
    commands = _command_after(Controller(defects=False), loc_speed=10.0, plan_v=1.7976931348623157e308)
    assert len(commands) == 20 and all(math.isfinite(c["acceleration"]) for c in commands)
