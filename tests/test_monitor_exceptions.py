"""The ``exceptions`` invariant kind: one line in a spec catches a module's logged exceptions and errors
(Python tracebacks, ERROR / FATAL lines, C++ terminate, segfault messages, an extra pattern), offline on
written lines and live on a real module process, and never on clean output."""

from __future__ import annotations

import sys
import textwrap

import pytest

from astaa_deft.io.log.reader import read_log
from astaa_deft.engine.monitor import check_log
from astaa_deft.engine.session import RunOptions, run_session
from astaa_deft.engine.spec.loader import load_spec

from monitor_helpers import HandMadeLog, line_of, load, spec_problems, spec_text

ERRORS = [
    "Traceback (most recent call last):",
    "2026-11-26 23:00:01,002 ERROR planner: no feasible path",
    "[FATAL] [1764197000.123] [planning]: lost the map",
    "CRITICAL:root:out of memory",
    "terminate called after throwing an instance of 'std::runtime_error'",
    "terminate called without an active exception",
    "Segmentation fault (core dumped)",
    "Fatal Python error: Segmentation fault",
    "Error:   RRTstar: There are no valid initial states!",
    "thread 'main' panicked at src/main.rs:4:5:",
    "panic: runtime error: index out of range [3] with length 3",
    'Exception in thread "main" java.lang.NullPointerException',
]
CLEAN = [
    "planning cycle 12: 3 candidates, 0 errors",
    "error budget: 0.2 m (recovered from an error state)",
    "ERRORS_SEEN=0",
    "Exception handling ready",
    "warning: slow step",
    "  last Error: none",
    "Exception in thread handling: none",
]


def lines_log(tmp_path, spec, lines):
    log = HandMadeLog(tmp_path / "run.mcap", spec)
    for k, (module, line) in enumerate(lines):
        log.event("module_log", 0.1 + 0.01 * k, module=module, stream="output", line=line)
    log.event("run_stopping", 5.0)
    return log.close()


def test_each_built_in_error_breaks_it_and_clean_lines_do_not(tmp_path):
    spec = load("- {name: planner_errors, kind: exceptions, modules: [planning]}\n")
    [invariant] = spec.invariants
    assert invariant.kind == "exceptions" and invariant.severity == "high" and invariant.max_count == 0
    lines = [("planning", line) for line in CLEAN + ERRORS] + [("control", ERRORS[0])]  # control: not watched
    result = check_log(lines_log(tmp_path, spec, lines), spec)
    assert [v.message["line"] for v in result.violations] == ERRORS
    assert {(v.invariant, v.invariant_kind, v.module, v.crash, v.severity) for v in result.violations} == {
        ("planner_errors", "exceptions", "planning", "Silent", "high")}
    assert result.violations[1].detail == f"module 'planning' logged an exception or error: {ERRORS[1]}"
    assert result.stats["planner_errors"] == {"evaluations": len(CLEAN) + len(ERRORS), "violating": len(ERRORS)}


def test_an_extra_pattern_matches_more_and_max_count_tolerates(tmp_path):
    spec = load('- {name: solver, kind: exceptions, pattern: "solver gave up", max_count: 1, severity: critical}\n')
    lines = [("control", "solver gave up at t=3"), ("sim", "step 4"), ("planning", "ERROR: no route"),
             ("planning", "solver gave up at t=5")]
    result = check_log(lines_log(tmp_path, spec, lines), spec)
    # every module by default; the first matching line tolerated
    assert [(v.module, v.message["line"], v.severity) for v in result.violations] == [
        ("planning", "ERROR: no route", "critical"), ("planning", "solver gave up at t=5", "critical")]


def test_bad_exceptions_invariants_are_one_clear_error_each():
    text = """
- {name: a, kind: exceptions, pattern: "([unclosed"}
- {name: b, kind: exceptions, modules: [nobody]}
- {name: c, kind: exceptions, max_count: -1}
- {name: d, kind: exceptions, modules: [planning], channel: trajectory}
"""
    problems = spec_problems(text)
    messages = [p.message for p in problems]
    assert any("not a regular expression" in m for m in messages)
    assert any("unknown module 'nobody'" in m for m in messages)
    assert any("'max_count' must be a whole number" in m for m in messages)
    assert any("unknown key 'channel'" in m for m in messages) and len(problems) == 4
    full = spec_text(text)
    assert {p.line for p in problems} == {line_of(full, f"name: {n}") for n in "abcd"}


@pytest.mark.parametrize("module", ["planning", "quiet"])
def test_a_real_module_traceback_breaks_it_live_and_offline_and_clean_output_does_not(tmp_path, module):
    (tmp_path / "planning.py").write_text(textwrap.dedent("""\
        import time, traceback
        print("planning ready", flush=True)
        time.sleep(0.3)
        try:
            route = []
            route[0]
        except IndexError:
            traceback.print_exc()  # logged, and the planner carries on
        print("planning cycle 2: 0 errors", flush=True)
        time.sleep(60)
        """))
    (tmp_path / "quiet.py").write_text(textwrap.dedent("""\
        import time
        print("quiet ready", flush=True)
        for k in range(20):
            print(f"cycle {k}: 0 errors, error budget 0.2 m, ERRORS_SEEN=0", flush=True)
            time.sleep(0.05)
        time.sleep(60)
        """))
    spec_path = tmp_path / "sut.yaml"
    spec_path.write_text(textwrap.dedent(f"""\
        name: exceptions
        modules:
          - {{name: {module}, command: ["{sys.executable}", "{tmp_path / (module + '.py')}"],
              ready: {{log: "{module} ready"}}}}
        channels:
          - {{name: plan, key: t/plan, producer: {module}, type: Plan}}
        types:
          Plan: {{seq: uint64}}
        invariants:
          - {{name: errors, kind: exceptions, modules: [{module}]}}
        """))
    spec = load_spec(spec_path)
    log_path = tmp_path / "run.mcap"
    result = run_session(spec, RunOptions(mode="star", record=log_path, time_limit=3.0))
    log = read_log(log_path)
    lines = [e["line"] for e in log.events("module_log")]
    offline = check_log(log, spec)
    if module == "planning":
        assert "Traceback (most recent call last):" in lines and any("IndexError" in line for line in lines)
        for judged in (result, offline):
            assert [(v.invariant, v.message["line"]) for v in judged.violations] == [
                ("errors", "Traceback (most recent call last):")]  # once per traceback, not per frame
            assert judged.verdict.klass == "Silent"
    else:
        assert len([line for line in lines if line.startswith("cycle")]) == 20
        assert not result.violations and not offline.violations
        assert result.verdict.klass == "Pass" and offline.verdict.klass == "Pass"
