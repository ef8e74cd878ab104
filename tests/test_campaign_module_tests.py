"""A bucket's module tests must fail on its defect, and the campaign says whether they do.

A planner that raises in a cycle answers nothing then, so DeFT's frames of
that run (one per recorded output) all replay fine and the suite passed. A
real run of the OMPL stack with its known defect 2 on (a NaN ego heading
makes the planner raise; the node logs it and carries on) shows the frame
of the failing cycle added, replayed by pytest in a fresh process, failing.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
import ompl  # noqa: F401  -- in the test extra; the stack's planner needs it (a venv without it fails, not skips)

from astaa_deft.orchestration.campaign.module_tests import (
    add_failure_frame, is_crash_bucket, judge_pytest, run_module_tests,
)
from astaa_deft.analysis.deft.workflow import ExtractOptions, extract_module_tests
from astaa_deft.engine.spec.loader import load_spec

STACK = Path(__file__).resolve().parent.parent / "examples" / "ompl_stack"
SPEC = STACK / "spec.yaml"


def test_what_counts_as_failing_on_the_defect():
    assert judge_pytest(0, "5 passed", crash=True).fails_on_defect is False
    oracle = "FAILED deft.json::oracle_invariant_000 - oracle invariant: frame 7: breaks plan_not_empty\n1 failed"
    assert judge_pytest(1, oracle, crash=False).fails_on_defect is True
    raised = ("frame 3: the planner's output changed\n  the planner raised ValueError: nan\n"
              "FAILED deft.json::frame_00003")
    assert judge_pytest(1, raised, crash=True).detail == "the replay raises ValueError: nan"
    assert judge_pytest(1, raised, crash=False).fails_on_defect is False  # raising is not a collision bucket's defect
    differs = "FAILED deft.json::frame_00003\nFAILED deft.json::frame_00004\n2 failed"
    assert judge_pytest(1, differs, crash=True) == judge_pytest(1, differs, crash=False)
    assert judge_pytest(1, differs, crash=True).fails_on_defect is False
    assert judge_pytest(4, "ERROR: file or directory not found", crash=True).fails_on_defect is None


def test_crash_buckets_are_exits_and_the_monitors_of_exceptions():
    spec = load_spec(SPEC)
    assert is_crash_bucket("Abort", "(module exit)", spec)
    assert is_crash_bucket("Silent", "planner_errors", spec)  # a log monitor of tracebacks
    assert not is_crash_bucket("Silent", "no_collision", spec)
    assert not is_crash_bucket("Silent", "plan_not_empty", spec)


@pytest.mark.slow  # ~1-2 min: a live run, then DeFT's candidate search over every planner output
def test_a_planner_that_raised_in_a_cycle_fails_its_module_tests_on_that_cycle(tmp_path):
    log = tmp_path / "nan_heading.mcap"
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"} | {"PYTHONPATH": str(Path.cwd())}
    res = subprocess.run([sys.executable, "-m", "astaa_deft.cli", "proxy", "--spec", str(SPEC), "--policy",
                          str(STACK / "defects" / "2_nan_heading.xml"), "--record", str(log), "--run-dir",
                          str(tmp_path / "run"), "--param", "defects=1", "--param", "goal_x=35"],
                         capture_output=True, text=True, timeout=180, env=env)
    assert res.returncode == 1 and "planner_errors" in res.stdout, res.stdout + res.stderr
    tests = tmp_path / "tests"
    report = extract_module_tests(log, SPEC, tests, ExtractOptions(jobs=1))
    assert report.accepted >= 1
    before = run_module_tests(tests, crash=True)
    assert before.fails_on_defect is False, before  # every recorded output replays: nothing fails
    assert add_failure_frame(tests, log, load_spec(SPEC), report, invariant="planner_errors")
    after = run_module_tests(tests, crash=True)
    assert after.fails_on_defect is True, after
    assert after.detail.startswith("the replay raises ValueError")
