"""The ``log`` invariant kind: a module's output lines.

A planner that catches an exception, logs it and carries on publishes
nothing for a cycle; before this kind no monitor could see it.
"""

from __future__ import annotations

import sys
import textwrap

from astaa_deft.io.log.reader import read_log
from astaa_deft.engine.monitor import check_log
from astaa_deft.engine.session import RunOptions, run_session
from astaa_deft.engine.spec.loader import load_spec

from monitor_helpers import HandMadeLog, line_of, load, spec_problems, spec_text

INVARIANTS = """
- {name: planner_quiet, kind: log, modules: [planning], pattern: "Traceback|ERROR"}
- {name: few_warnings, kind: log, pattern: "WARN", max_count: 1, crash: Hindering}
"""


def test_matching_lines_beyond_max_count_break_it_offline(tmp_path):
    spec = load(INVARIANTS)
    log = HandMadeLog(tmp_path / "run.mcap", spec)
    for at, module, line in [(0.5, "planning", "planning cycle 1"), (0.7, "control", "ERROR in control"),
                             (0.9, "planning", "Traceback (most recent call last):"),
                             (1.0, "sim", "WARN slow step"), (1.1, "control", "WARN late command")]:
        log.event("module_log", at, module=module, stream="output", line=line)
    log.event("run_stopping", 2.0)
    result = check_log(log.close(), spec)
    found = [(v.invariant, v.module, v.crash) for v in result.violations]
    # control's ERROR is not planning's business; the first WARN is tolerated, the second is not.
    assert found == [("planner_quiet", "planning", "Silent"), ("few_warnings", "control", "Hindering")]
    assert "Traceback" in result.violations[0].detail
    assert result.stats["planner_quiet"] == {"evaluations": 2, "violating": 1}


def test_bad_log_invariants_are_one_clear_error_each():
    text = """
- {name: a, kind: log, pattern: "([unclosed"}
- {name: b, kind: log, modules: [nobody], pattern: "x"}
- {name: c, kind: log, pattern: "x", max_count: -1}
- {name: d, kind: log}
"""
    problems = spec_problems(text)
    messages = [p.message for p in problems]
    full = spec_text(text)
    assert any("not a regular expression" in m for m in messages)
    assert any("unknown module 'nobody'" in m for m in messages)
    assert any("'max_count' must be a whole number" in m for m in messages)
    assert any("'pattern'" in m for m in messages) and len(problems) == 4
    assert {p.line for p in problems} == {line_of(full, f"name: {n}") for n in "abcd"}


def test_a_logged_and_survived_exception_is_caught_live_and_again_offline(tmp_path):
    planner = textwrap.dedent("""\
        import sys, time
        print("planner ready", flush=True)
        time.sleep(0.5)
        print("Traceback (most recent call last):", flush=True)
        print("ValueError: no feasible path (logged, planner carries on)", file=sys.stderr, flush=True)
        time.sleep(60)
        """)
    (tmp_path / "planner.py").write_text(planner)
    spec_path = tmp_path / "sut.yaml"
    spec_path.write_text(textwrap.dedent(f"""\
        name: logged
        modules:
          - {{name: planning, command: ["{sys.executable}", "{tmp_path / 'planner.py'}"], ready: {{log: "planner ready"}}}}
        channels:
          - {{name: plan, key: t/plan, producer: planning, type: Plan}}
        types:
          Plan: {{seq: uint64}}
        invariants:
          - {{name: planner_quiet, kind: log, modules: [planning], pattern: "Traceback|Error"}}
        """))
    spec = load_spec(spec_path)
    log_path = tmp_path / "run.mcap"
    result = run_session(spec, RunOptions(mode="star", record=log_path, time_limit=20.0,
                                          stop_on_violation=True))
    assert result.end_reason.startswith("violation")
    assert [v.invariant for v in result.violations][:1] == ["planner_quiet"]
    assert result.verdict.klass == "Silent"
    log = read_log(log_path)
    lines = [e["line"] for e in log.events("module_log")]
    assert "Traceback (most recent call last):" in lines
    offline = check_log(log, spec)
    assert [v.invariant for v in offline.violations][:1] == ["planner_quiet"]
    assert offline.verdict.klass == "Silent"
