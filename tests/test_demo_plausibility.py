"""Inputs no car or road of the demo has: with defects off, the demo modules ignore them.

Each was found by a campaign with the defects off (benchmarks/bench_campaign.py's
false alarms): not seeded defects, but real gaps of the demo stack that made
a clean stack fail under one mutated message. The modules' own logic, run
in-process (the planner's and the controller's pure classes).
"""

from __future__ import annotations

import math

import pytest

from astaa_deft.demo.control import FALLBACK_BRAKE, Controller
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


# ---------------------------------------------------------------- stamps (the generator's stamp family)

def _with_prediction_stamp(stamp: float, loc_stamp: float) -> dict:
    """A frame whose trigger (prediction) carries ``stamp``; the other inputs carry the real time."""
    corrupted = frame(stamp=loc_stamp)
    corrupted["prediction"] = dict(corrupted["prediction"], header={"seq": 1, "stamp": stamp})
    return corrupted


@pytest.mark.parametrize("defects", [False, True])  # the planning clock is not a seeded defect
@pytest.mark.parametrize("bad", [math.nan, 4102444800.0, -1.0])  # NaN, 2100-01-01, a jump back
def test_a_bad_trigger_stamp_held_keeps_the_plans_coming_on_a_clock_that_steps_on(defects, bad):
    planner = Planner(defects=defects)
    plans = [planner.step(frame(stamp=1.0 + 0.1 * k)) for k in range(3)]
    plans += [planner.step(_with_prediction_stamp(bad, 1.3 + 0.1 * k)) for k in range(20)]  # 2 s held
    plans += [planner.step(frame(stamp=3.3 + 0.1 * k)) for k in range(3)]  # real stamps again
    stamps = [p["header"]["stamp"] for p in plans]
    assert stamps == pytest.approx([1.0 + 0.1 * k for k in range(26)])  # every cycle on the true clock
    assert all(p["points"] and p["points"][0]["t"] == pytest.approx(p["header"]["stamp"]) for p in plans)
    assert all(math.isfinite(v) for p in plans for point in p["points"] for v in point.values())


def test_a_lost_stretch_of_triggers_is_followed_not_taken_for_a_bad_stamp():
    planner = Planner(defects=False)
    planner.step(frame(stamp=1.0))
    assert planner.step(frame(stamp=4.0))["header"]["stamp"] == 4.0  # 3 s without triggers: real time


def test_a_trigger_a_few_periods_old_is_planned_at_its_own_time():
    """DeFT replaying a neighbouring trigger, or a reordered message: the plan is the one its stamp gives."""
    planner = Planner(defects=True)
    planner.step(frame(stamp=1.3))
    late = planner.step(frame(stamp=1.0))
    assert late["header"]["stamp"] == 1.0 and late["points"][0]["t"] == 1.0


def _localizations(controller: Controller, stamps: list[float]) -> list[dict | None]:
    points = [{"t": 1.0 + 0.1 * k, "x": 10.0 * (1.0 + 0.1 * k), "y": 0.0, "heading": 0.0, "v": 10.0, "a": 2.0}
              for k in range(101)]
    controller.on_trajectory({"header": {"seq": 1, "stamp": 1.0}, "points": points})
    return [controller.on_localization(Localization(stamp, 10.0, 0.0, 0.0, 5.0, 0.0, 0.0)) for stamp in stamps]


def test_a_far_future_localization_stamp_is_ignored_and_a_held_one_brakes_with_defects_off():
    real = [1.0 + 0.02 * k for k in range(5)]
    held = [4102444800.0] * 30  # 0.6 s of localizations stamped 2100-01-01
    commands = _localizations(Controller(defects=False), real + held + [real[-1] + 0.02 * k for k in range(31, 36)])
    accelerations = [c["acceleration"] for c in commands if c is not None]
    assert accelerations[4] > 0.0  # following the plan: speeding up from 5 to 10 m/s
    blind = accelerations[5:35]
    assert blind[:10] == [accelerations[4]] * 10  # a few unusable ones: the last command
    assert blind[10:] == [FALLBACK_BRAKE] * 20  # held: it brakes rather than accelerate blind
    assert accelerations[35:] and all(a > 0.0 for a in accelerations[35:])  # real stamps again: followed


@pytest.mark.filterwarnings("ignore:invalid value encountered:RuntimeWarning")  # defect 4's own division
def test_a_held_jump_back_brakes_with_defects_off_and_stays_seeded_defect_4_with_defects_on():
    real = [1.0 + 0.02 * k for k in range(5)]
    back = [real[-1] - 1.0] * 15
    off = [c["acceleration"] for c in _localizations(Controller(defects=False), real + back) if c is not None]
    assert off[-1] == FALLBACK_BRAKE and all(math.isfinite(a) for a in off)
    on = [c["acceleration"] for c in _localizations(Controller(defects=True), real + back[:1]) if c is not None]
    assert not math.isfinite(on[-1])  # seeded defect 4, unchanged
