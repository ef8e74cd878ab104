"""Temporal invariants: multi-rate sampling, reported samples, and rtamt's semantics kept intact."""

from __future__ import annotations

import math
import random
from fractions import Fraction

import pytest
from monitor_helpers import HandMadeLog, lights, load, ns, obstacle, obstacles, pose

from astaa_deft.engine.monitor import check_log
from astaa_deft.engine.monitor.stl import _rtamt, check_formula

STOP_AT_RED = """
- name: stop_at_red
  kind: temporal
  period: 0.1
  signals:
    red:    {channel: lights, expr: "len(lights) > 0 and lights[0].state == 'red'"}
    stop_x: {channel: lights, expr: "lights[0].stop_line_x"}
    ego_x:  {channel: localization, field: x}
    speed:  {channel: localization, field: speed}
  formula: "always((red and stop_x - ego_x >= 0 and stop_x - ego_x <= 5) implies eventually[0:2](speed < 0.5))"
"""


def drive(tmp_path, invariants: str, speed_at, light_at, x_at=lambda t: 97.0, seconds: float = 8.0):
    """Lights at 10 Hz, localization at 50 Hz (offset by 1 ms): two channels at different rates."""
    spec = load(invariants)
    log = HandMadeLog(tmp_path / "run.mcap", spec)
    for k in range(int(seconds * 10) + 1):
        log.message("lights", 0.1 * k, lights(k, light_at(0.1 * k)))
    for k in range(int(seconds * 50)):
        t = 0.02 * k + 0.001
        log.message("localization", t, pose(k, x=x_at(t), speed=speed_at(t)))
    return check_log(log.close(), spec)


def test_not_stopping_at_a_red_light_is_reported_at_the_first_sample_it_fails(tmp_path):
    result = drive(tmp_path, STOP_AT_RED, speed_at=lambda t: 3.0, light_at=lambda t: "red" if t >= 2.95 else "green")
    (found,) = result.violations
    # The light turns red in the lights message at 3.0 s; the sample at 3.0 s sees it (at or before).
    assert (found.invariant, found.time_ns, found.channel, found.seq) == ("stop_at_red", ns(3.0), "lights", 31)
    assert found.message["signals"] == {"red": True, "stop_x": 100.0, "ego_x": 97.0, "speed": 3.0}
    assert found.message["robustness"] < 0 and "decided 2 s later" in found.detail
    # samples are judged from the start up to 2 s (the horizon) before the end of the run
    assert result.stats["stop_at_red"]["evaluations"] == pytest.approx(80 - 20, abs=1)


def test_stopping_within_two_seconds_passes(tmp_path):
    result = drive(tmp_path, STOP_AT_RED, speed_at=lambda t: 3.0 if t < 4.5 else 0.2,
                   light_at=lambda t: "red" if t >= 2.95 else "green")
    assert result.violations == []
    assert result.verdict.klass == "Pass"


def test_far_from_the_stop_line_nothing_is_required(tmp_path):
    result = drive(tmp_path, STOP_AT_RED, speed_at=lambda t: 3.0, light_at=lambda t: "red", x_at=lambda t: 50.0)
    assert result.violations == []


def test_a_failure_whose_deadline_lies_past_the_end_of_the_run_is_not_judged(tmp_path):
    result = drive(tmp_path, STOP_AT_RED, speed_at=lambda t: 3.0, light_at=lambda t: "red" if t >= 6.5 else "green")
    assert result.violations == []  # red at 6.5 s, the run ends at 8 s: the car still had 0.5 s


def test_never_closer_than_half_a_metre_multi_rate(tmp_path):
    spec = load("""
        - name: keep_distance
          kind: temporal
          signals:
            ego_x:  {channel: localization, field: x}
            lead_x: {channel: obstacles, expr: "obstacles[0].x"}
          formula: "always(lead_x - ego_x >= 0.5)"
        """)
    log = HandMadeLog(tmp_path / "run.mcap", spec)
    for k in range(30):  # the lead car stands at 10 m, reported at 10 Hz
        log.message("obstacles", 0.1 * k + 0.05, obstacles(k, obstacle(1, 10.0)))
    for k in range(150):  # the ego creeps forward at 5 m/s, reported at 50 Hz
        log.message("localization", 0.02 * k, pose(k, x=0.05 * k * 2))
    (found,) = check_log(log.close(), spec).violations
    # ego_x = 0.1 k reaches 9.6 (gap 0.4) with message #97 at 1.92 s; the next grid point is 2.0 s
    assert (found.time_ns, found.channel) == (ns(2.0), "localization")
    assert found.message["signals"]["lead_x"] == 10.0 and 9.5 < found.message["signals"]["ego_x"] <= 10.0


def test_a_sample_sees_messages_at_or_before_its_time_and_holds_through_bad_values(tmp_path):
    spec = load("""
        - name: x_small
          kind: temporal
          signals: {x: {channel: localization, field: x}}
          formula: "x < 5"
        """)
    log = HandMadeLog(tmp_path / "run.mcap", spec)
    log.message("localization", 0.0, pose(0, x=1.0))
    log.message("localization", 0.35, pose(1, x=math.nan))  # not a value: x stays 1.0
    log.message("localization", 0.5, pose(2, x=7.0))  # exactly on a grid point: seen by the 0.5 s sample
    log.message("localization", 0.61, pose(3, x=1.0))
    log.message("localization", 0.9, pose(4, x=1.0))
    log.message("localization", 1.01, pose(5, x=8.0))  # just after a grid point: first seen at 1.1 s
    log.message("localization", 1.3, pose(6, x=8.0))
    found = check_log(log.close(), spec).violations
    assert [(v.time_ns, v.seq) for v in found] == [(ns(0.5), 3), (ns(1.1), 6)]


# rtamt's pastifier (0.4.10) delays comparisons under a future operator twice; ours must agree with
# rtamt's own offline evaluation of the whole trace, which needs no pastification.
FORMULAS = [
    "a > 0 implies eventually[0:0.3](b < 1)",
    "historically[0:0.2](a > 0) or eventually[0:0.5](b > 2)",
    "always[0:0.3](historically[0:0.2](a > -1))",
    "a until[0:0.4] (b > 1)",
    "eventually[0:0.2](a > 0) since[0:0.5] (b > 2)",
    "rise(a > 0) implies eventually[0.1:0.2](abs(a - b) < 1)",
]


@pytest.mark.parametrize("formula", FORMULAS)
def test_online_pastified_verdicts_equal_rtamt_offline_evaluation(formula):
    rtamt = _rtamt()
    rng = random.Random(formula)
    n = 60
    a = [rng.choice([-2.0, -1.0, 0.5, 1.5, 2.0]) for _ in range(n)]
    b = [rng.choice([0.0, 0.8, 1.5, 2.5]) for _ in range(n)]
    offline = rtamt.StlDiscreteTimeSpecification()
    for name in "ab":
        offline.declare_var(name, "float")
    offline.spec = formula
    offline.set_sampling_period(100, "ms", 0.1)
    offline.parse()
    expected = [r for _, r in offline.evaluate({"time": [k * 0.1 for k in range(n)], "a": a, "b": b})]

    online = check_formula(formula, ["a", "b"], Fraction(1, 10)).online_monitor()
    got = [online.update([("a", a[k]), ("b", b[k])]) for k in range(n)]
    judged = [r for r in got if r is not None]  # sample k's verdict arrives horizon samples later
    assert len(judged) == n - online.formula.horizon_samples
    assert judged == pytest.approx(expected[:len(judged)])


PREV = """
- name: x_never_falls
  kind: temporal
  period: 0.1
  signals:
    x: {channel: localization, field: x}
  formula: "always(x >= prev x)"
"""


def test_prev_at_the_first_sample_is_the_sample_itself_so_a_monotone_signal_holds_there(tmp_path):
    # rtamt alone gives prev x = +inf at the first sample, and this formula failed there
    (tmp_path / "rising").mkdir()
    (tmp_path / "falling").mkdir()
    rising = drive(tmp_path / "rising", PREV, speed_at=lambda t: 1.0, light_at=lambda t: "green",
                   x_at=lambda t: 10.0 + t, seconds=2.0)
    assert rising.violations == [] and rising.stats["x_never_falls"]["evaluations"] >= 19
    falling = drive(tmp_path / "falling", PREV, speed_at=lambda t: 1.0, light_at=lambda t: "green",
                    x_at=lambda t: 10.0 - t, seconds=2.0)
    [found] = falling.violations
    assert found.time_ns == ns(0.2)  # the first sample (0.1 s) holds: prev x is x; the second, lower, breaks it
