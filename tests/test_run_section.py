"""The spec's `run:` section: how a run ends (a module's exit, a channel's message, a time limit) and what it means.

Real subprocess modules on a real Zenoh bus (loopback); bad input through
the loader and the real CLI.
"""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from astaa_deft.model.errors import InputError
from astaa_deft.engine.session import RunOptions, run_session
from astaa_deft.engine.spec.loader import load_spec, load_spec_text

ENDER = Path(__file__).parent / "sut" / "ender.py"
SAFETY_LIMIT = 30.0  # the caller's own limit: a run that ignored its end would hit this


IDLE = "import time; time.sleep(600)"
# Takes a second to stop: the run's shutdown lasts longer than a short deadline.
SLOW_TO_STOP = ("import signal, sys, time; "
                "[signal.signal(s, lambda *a: (time.sleep(1.0), sys.exit(0))) for s in (signal.SIGINT, signal.SIGTERM)]; "
                "time.sleep(600)")


def _spec(tmp_path: Path, run: str, exit_code: int = -1, done_after: int = 8, extra_invariants: str = "",
          idle: str = IDLE) -> Path:
    text = textwrap.dedent(f"""\
        name: ender
        modules:
          - name: sim
            command: ["{{python}}", "{ENDER}", "--key", "t/status", "--done-after", "{done_after}",
                      "--exit-code", "{exit_code}"]
          - name: idle
            command: ["{{python}}", "-c", "{idle}"]
        channels:
          - {{name: status, key: t/status, producer: sim, consumers: [], type: Status}}
        types:
          Header: {{seq: uint64, stamp: time}}
          Status: {{header: Header, done: bool, count: uint32}}
        invariants:
          - {{name: modules_alive, kind: process}}
        """) + extra_invariants + textwrap.dedent(run)
    path = tmp_path / "ender.yaml"
    path.write_text(text)
    return path


def _offline(spec_path: Path, tmp_path: Path):
    """`check` over the run's log: it must name the same verdict and findings as the online monitors."""
    from astaa_deft.io.log.reader import read_log
    from astaa_deft.engine.monitor import check_log

    return check_log(read_log(tmp_path / "run.mcap"), load_spec(spec_path))


def _run(spec_path: Path, tmp_path: Path, time_limit: float = SAFETY_LIMIT):
    spec = load_spec(spec_path)
    options = RunOptions(record=tmp_path / "run.mcap", run_dir=tmp_path / "run", time_limit=time_limit)
    return run_session(spec, options)


def test_a_module_whose_exit_ends_the_run_with_code_0_gives_a_pass(tmp_path):
    spec = _spec(tmp_path, exit_code=0, run="""
        run:
          end_when:
            - {module: sim, reason: scenario over}
        """)
    result = _run(spec, tmp_path)
    assert result.end_reason == "scenario over"
    assert result.seconds < SAFETY_LIMIT / 2
    assert result.verdict.klass == "Pass", result.verdict.summary  # not Hindering: the exit is the end
    assert result.passed and not result.crashes


def test_an_exit_code_declared_as_an_outcome_is_a_finding_with_its_crash_class(tmp_path):
    spec = _spec(tmp_path, exit_code=1, run="""
        run:
          end_when:
            - module: sim
              exit_codes:
                - {code: 0, outcome: pass}
                - {code: 1, outcome: collision, crash: Silent, severity: critical}
        """)
    result = _run(spec, tmp_path)
    assert result.end_reason == "module 'sim' exited"
    assert result.verdict.klass == "Silent", result.verdict.summary
    [finding] = result.violations
    assert finding.invariant == "run_end:collision" and finding.severity == "critical" and finding.module == "sim"
    assert not result.crashes  # the code is an outcome, not an Abort on top of it
    offline = _offline(spec, tmp_path)
    assert offline.verdict.klass == "Silent" and [v.invariant for v in offline.violations] == ["run_end:collision"]


def test_an_exit_code_the_spec_does_not_list_is_a_crash(tmp_path):
    spec = _spec(tmp_path, exit_code=3, run="""
        run:
          end_when:
            - module: sim
              exit_codes: [{code: 0, outcome: pass}, {code: 1, outcome: collision}]
        """)
    result = _run(spec, tmp_path)
    assert result.verdict.klass == "Abort", result.verdict.summary
    assert [v.invariant for v in result.violations] == ["run_end:crashed"]


def test_a_channel_that_says_done_ends_the_run_as_a_pass(tmp_path):
    spec = _spec(tmp_path, exit_code=-1, done_after=10, run="""
        run:
          end_when:
            - {channel: status, expr: "done == True", reason: goal}
        """)
    result = _run(spec, tmp_path)
    assert result.end_reason == "goal"
    assert result.seconds < SAFETY_LIMIT / 2
    assert result.passed, result.verdict.summary


def test_a_channel_condition_with_a_crash_class_is_a_finding(tmp_path):
    spec = _spec(tmp_path, exit_code=-1, done_after=6, run="""
        run:
          end_when:
            - {channel: status, expr: "count >= 3 and not done", reason: stuck, crash: Hindering}
        """)
    result = _run(spec, tmp_path)
    assert result.end_reason == "stuck"
    assert result.verdict.klass == "Hindering"
    [finding] = result.violations
    assert finding.channel == "status" and finding.message["count"] == 3


def test_the_spec_time_limit_ends_a_run_that_never_ends_by_itself(tmp_path):
    spec = _spec(tmp_path, exit_code=-1, done_after=10**6, run="""
        run:
          time_limit: 1.5
          end_when:
            - {channel: status, expr: "done", reason: goal}
        """)
    result = _run(spec, tmp_path)
    assert result.end_reason == "time limit"
    assert 1.4 < result.seconds < SAFETY_LIMIT / 2
    assert result.passed


def test_no_deadline_finding_after_the_run_ended(tmp_path):
    # The status stops with the sim's exit; a 0.3 s deadline must not fire during the shutdown that follows.
    spec = _spec(tmp_path, exit_code=0, idle=SLOW_TO_STOP, extra_invariants="""\
  - {name: status_alive, kind: deadline, channel: status, max_gap: 0.3}
""", run="""
        run:
          end_when: [{module: sim}]
        """)
    result = _run(spec, tmp_path)
    assert result.verdict.klass == "Pass", result.verdict.summary
    offline = _offline(spec, tmp_path)
    assert offline.verdict.klass == "Pass" and offline.violations == [], offline.verdict.summary


# -- bad input -----------------------------------------------------------------

BASE = textwrap.dedent("""\
    name: s
    modules:
      - {name: sim, command: [x]}
    channels:
      - {name: status, key: t/status, producer: sim, consumers: [], type: Status}
    types:
      Status: {done: bool, count: uint32}
    """)


def _problems(run: str) -> list[str]:
    with pytest.raises(InputError) as info:
        load_spec_text(BASE + textwrap.dedent(run), name="s.yaml")
    return [str(p) for p in info.value.problems]


@pytest.mark.parametrize("run, line, col, words", [
    ("run:\n  time_limt: 3\n", 9, 3, ["unknown key 'time_limt'", "did you mean 'time_limit'"]),
    ("run:\n  time_limit: -1\n", 9, 15, ["greater than 0"]),
    ("run:\n  end_when: {module: sim}\n", 9, 13, ["non-empty list"]),
    ("run:\n  end_when: [{module: simm}]\n", 9, 23, ["unknown module 'simm'", "did you mean 'sim'"]),
    ("run:\n  end_when: [{channel: status, expr: \"done ==\", reason: r}]\n", 9, 46, ["not a valid expression"]),
    ("run:\n  end_when: [{channel: status, expr: \"speed > 1\", reason: r}]\n", 9, 39, ["speed"]),
    ("run:\n  end_when: [{channel: status, expr: \"count\", reason: r}]\n", 9, 39, ["condition"]),
    ("run:\n  end_when: [{channel: status, expr: done}]\n", 9, 14, ["lacks 'reason'"]),
    ("run:\n  end_when: [{channel: status, module: sim}]\n", 9, 14, ["either a 'module'"]),
    ("run:\n  end_when: [{module: sim, exit_codes: [{code: 300, outcome: pass}]}]\n", 9, 48, ["0 to 255"]),
    ("run:\n  end_when: [{module: sim, exit_codes: [{code: 1, outcome: x, crash: Boom}]}]\n", 9, 70,
     ["'crash' must be one of"]),
    ("run:\n  end_when: [{module: sim, exit_codes: [{code: 0, outcome: pass, crash: Silent}]}]\n", 9, 41,
     ["is 'pass'"]),
    ("run:\n  end_when: [{module: sim}, {module: sim}]\n", 9, 38, ["named twice"]),
])
def test_a_bad_run_section_is_one_clear_problem_with_its_place_and_a_fix(run, line, col, words):
    problems = _problems(run)
    assert len(problems) == 1, problems
    text = problems[0]
    assert text.startswith(f"s.yaml:{line}:{col}"), text
    for word in words:
        assert word in text, text


def test_spec_check_reports_a_bad_run_section_with_exit_2_and_no_traceback(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text(BASE + "run:\n  end_when: [{channel: stat, expr: done, reason: r}]\n")
    done = subprocess.run([sys.executable, "-m", "astaa_deft.cli", "spec", "check", str(path)],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 2
    assert "Traceback" not in done.stderr + done.stdout
    assert f"{path}:9:" in done.stderr + done.stdout and "unknown channel 'stat'" in done.stderr + done.stdout


def test_the_demo_spec_declares_its_end_in_its_run_section():
    from astaa_deft.demo.bundled import demo_spec_path

    run = load_spec(demo_spec_path()).run
    assert run.time_limit is not None
    assert {end.reason for end in run.channel_ends} >= {"goal reached", "collision"}
