"""The run verdict on the CRASH scale, the `check` command, and online/offline agreement."""

from __future__ import annotations

import json
import math
import random

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
    spec_text,
    trajectory,
)

from astaa_deft.io.codecs import get_codec
from astaa_deft.cli.commands import check as check_command
from astaa_deft.model.errors import InputError
from astaa_deft.io.log import layout
from astaa_deft.engine.monitor import MonitorSet, Violation, check_log, run_verdict
from astaa_deft.engine.monitor.verdict import IMPLICIT
from astaa_deft.model.records import ProcessExit

MODULES = ("sim", "planning", "control")


def violation(invariant="inv", kind="bound", crash="Silent", at=1.0, module="control") -> Violation:
    return Violation(invariant=invariant, invariant_kind=kind, severity="high", time_ns=ns(at), channel="command",
                     seq=3, message=None, detail="broke", crash=crash, module=module)


def exit_event(module, at, returncode=1, signal=None, during_shutdown=False) -> ProcessExit:
    return ProcessExit(module=module, pid=0, returncode=returncode, signal=signal, time_ns=ns(at),
                       during_shutdown=during_shutdown)


@pytest.mark.parametrize("violations, exits, expected", [
    ([], [], "Pass"),
    ([], [exit_event(m, 9.0, during_shutdown=True) for m in MODULES], "Pass"),
    ([violation()], [], "Silent"),
    ([violation(crash="Hindering")], [], "Hindering"),
    ([], [exit_event("control", 2.0, returncode=0)], "Hindering"),  # "success", but it stopped serving
    ([violation()], [exit_event("control", 2.0, signal="SIGSEGV", returncode=-11)], "Abort"),
    ([violation(kind="deadline", crash="Restart", at=3.0)], [], "Restart"),  # silent while alive: a hang
    # silent *after* its module crashed: the crash's consequence, not a hang
    ([violation(kind="deadline", crash="Restart", at=3.0)], [exit_event("control", 2.0)], "Abort"),
    ([violation()], [exit_event(m, 2.0 + i) for i, m in enumerate(MODULES)], "Catastrophic"),
])
def test_crash_scale_mapping(violations, exits, expected):
    assert run_verdict(violations, exits, MODULES).klass == expected


def test_a_lost_bus_makes_the_run_catastrophic():
    assert run_verdict([], [], MODULES, bus_lost=True).klass == "Catastrophic"


def test_the_first_finding_is_the_earliest_and_exits_count_without_a_process_invariant():
    late = violation("late", at=5.0)
    verdict = run_verdict([late], [exit_event("planning", 1.5, signal="SIGKILL", returncode=-9)], MODULES)
    assert verdict.klass == "Abort"
    assert verdict.first.invariant == IMPLICIT and verdict.first.module == "planning"
    assert "SIGKILL" in verdict.summary
    assert json.loads(json.dumps(verdict.to_json()))["class"] == "Abort"


# ---------------------------------------------------------------- the check command

INVARIANTS = """
- {name: finite_cmd, kind: bound, channel: command, field: acceleration, finite: true}
- {name: traj_deadline, kind: deadline, channel: trajectory, max_gap: 0.5}
"""


def write_run(path, nan_at: int | None = None, crash: bool = False):
    spec = load(INVARIANTS)
    log = HandMadeLog(path, spec)
    log.writer.attachment(layout.SPEC_ATTACHMENT, spec_text(INVARIANTS).encode(), "application/yaml")
    for k in range(30):
        log.message("command", 0.1 * k, command(k, math.nan if k == nan_at else 0.5))
        log.message("trajectory", 0.1 * k + 0.02, trajectory(k))
    if crash:
        log.exit("control", 2.0, returncode=-6, signal="SIGABRT")
    log.close()
    return path


def test_check_exit_codes_and_output(tmp_path, capsys):
    spec_path = tmp_path / "sut.yaml"
    spec_path.write_text(spec_text(INVARIANTS))
    assert check_command.check_log(write_run(tmp_path / "ok.mcap"), spec_path) == 0
    assert "verdict: Pass" in capsys.readouterr().out

    assert check_command.check_log(write_run(tmp_path / "nan.mcap", nan_at=12), spec_path) == 1
    out = capsys.readouterr().out
    assert "finite_cmd (bound) on 'command' #13 at +1.200 s" in out and "verdict: Silent" in out

    assert check_command.check_log(write_run(tmp_path / "crash.mcap", crash=True), None) == 1  # spec from the log
    assert "verdict: Abort" in capsys.readouterr().out


def test_check_json_output(tmp_path, capsys):
    assert check_command.check_log(write_run(tmp_path / "nan.mcap", nan_at=3), None, as_json=True) == 1
    body = json.loads(capsys.readouterr().out)
    assert body["verdict"]["class"] == "Silent"
    assert [(v["invariant"], v["seq"]) for v in body["violations"]] == [("finite_cmd", 4)]


def test_check_input_errors(tmp_path):
    spec = load(INVARIANTS)
    bare = HandMadeLog(tmp_path / "bare.mcap", spec)
    bare.close()
    with pytest.raises(InputError, match="holds no spec"):
        check_command.check_log(tmp_path / "bare.mcap", None)
    with pytest.raises(InputError, match="not found"):
        check_command.check_log(tmp_path / "missing.mcap", None)
    bad_spec = tmp_path / "bad.yaml"
    bad_spec.write_text(spec_text("- {name: a, kind: bound, channel: command, field: accel, min: 0}"))
    with pytest.raises(InputError) as caught:
        check_command.check_log(write_run(tmp_path / "run.mcap"), bad_spec)
    assert caught.value.problems[0].file == str(bad_spec) and caught.value.problems[0].line


def test_the_offline_check_is_a_library_call_that_prints_nothing(tmp_path, capsys):
    from astaa_deft.engine.session.check import check_recorded_run

    checked = check_recorded_run(write_run(tmp_path / "nan.mcap", nan_at=12))
    assert capsys.readouterr().out == ""
    assert checked.spec_from_log and not checked.passed and checked.result.verdict.klass == "Silent"
    assert [v.invariant for v in checked.result.violations] == ["finite_cmd"]
    assert len(checked.spec.invariants) == 2


# ---------------------------------------------------------------- online and offline agree

EVERY_KIND = """
- {name: finite_cmd, kind: bound, channel: command, field: acceleration, finite: true, min: -8, max: 4}
- {name: speeds, kind: bound, channel: trajectory, field: "points[*].v", min: 0}
- {name: speed_limit, kind: expression, channel: status, expr: "ego_speed <= speed_limit + 0.5"}
- {name: traj_deadline, kind: deadline, channel: trajectory, max_gap: 0.5}
- {name: control_answers, kind: deadline, channel: command, responds_to: localization, max_gap: 0.3}
- {name: control_alive, kind: process, modules: [control]}
- name: no_collision
  kind: collision
  ego: {channel: localization, length: 4.5, width: 1.9}
  obstacles: {channel: obstacles, array: obstacles, id: id}
- name: stop_at_red
  kind: temporal
  signals:
    red:   {channel: lights, expr: "lights[0].state == 'red'"}
    speed: {channel: localization, field: speed}
  formula: "always(red implies eventually[0:1](speed < 0.5))"
"""


def scenario():
    """(channel, seconds, value) of a run that breaks every kind once, in time order."""
    out = []
    for k in range(80):
        t = 0.1 * k + 0.013  # off the 0.1 s sampling grid by more than any jitter below
        if k < 70:  # control crashes at 7.0 s
            out.append(("command", t, command(k, math.nan if k == 13 else 0.5)))
        if not 20 <= k < 28:
            out.append(("trajectory", t + 0.01, trajectory(k, (5.0, -1.0 if k == 40 else 3.0))))
        out.append(("status", t + 0.02, {"ego_speed": 12.0 if k == 33 else 10.0, "speed_limit": 11.0, "mode": "a"}))
        out.append(("localization", t + 0.03, pose(k, x=k * 0.5, speed=3.0)))
        out.append(("obstacles", t + 0.04, obstacles(k, obstacle(7, 30.0))))
        out.append(("lights", t + 0.05, lights(k, "red" if k >= 50 else "green")))
    return out


def test_online_and_offline_verdicts_agree_on_the_same_run(tmp_path):
    spec = load(EVERY_KIND)
    messages = scenario()
    crash_at = 7.0

    # offline: the recorder's view, logged and checked
    log = HandMadeLog(tmp_path / "run.mcap", spec)
    for channel, t, value in messages:
        log.message(channel, t, value)
    log.exit("control", crash_at, returncode=-11, signal="SIGSEGV")
    log.event("run_stopping", 8.0)
    offline = check_log(log.close(), spec)

    # online: the tool's view of the same messages, received up to 2 ms apart from the recorder's, in its
    # own receive order, with ticks every 50 ms, the exit as the launcher reports it, then the stop
    rng = random.Random(7)
    online_view = sorted(((ns(t) + rng.randint(-2_000_000, 2_000_000), channel, value)
                          for channel, t, value in messages), key=lambda m: m[0])
    monitors = MonitorSet(spec, ns(0.0))
    counters: dict[str, int] = {}
    next_tick = ns(0.05)
    exit_pending = True
    for time_ns, channel, value in online_view:
        while next_tick <= time_ns:
            monitors.on_tick(next_tick)
            next_tick += 50_000_000
        if exit_pending and time_ns >= ns(crash_at):
            monitors.on_process_exit("control", -11, "SIGSEGV", ns(crash_at), during_shutdown=False, stderr_tail="")
            exit_pending = False
        counters[channel] = counters.get(channel, 0) + 1
        payload = get_codec(spec.channel(channel).encoding).encode(value)
        decoded = get_codec(spec.channel(channel).encoding).decode(payload)
        monitors.on_message(channel, time_ns, decoded, counters[channel])
    monitors.finish(ns(8.0))
    online = monitors.violations

    def key(v):
        return v.invariant, v.channel, v.seq, v.module

    assert sorted(map(key, online)) == sorted(map(key, offline.violations))
    assert {v.invariant for v in offline.violations} == {
        "finite_cmd", "speeds", "speed_limit", "traj_deadline", "control_answers", "control_alive", "no_collision",
        "stop_at_red"}
    by_name = {v.invariant: v for v in offline.violations}
    for v in online:  # dated by the same messages, so within the receive-time jitter
        assert abs(v.time_ns - by_name[v.invariant].time_ns) <= 2_000_000
    assert monitors.verdict().klass == offline.verdict.klass == "Restart"
    assert monitors.verdict().first.invariant == offline.verdict.first.invariant == "finite_cmd"
