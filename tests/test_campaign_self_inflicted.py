"""Self-inflicted findings of a campaign case, judged on the producers' originals.

A collision invariant reads two channels (the ego and the obstacles). A case
that rewrites the obstacles can make the monitors see a collision that
exists only in the rewritten messages — or mislead the planner into a real
one. Real runs of examples/ompl_stack through the star (real planner and
simulator processes, loopback Zenoh, real MCAP logs with the originals)
decide which: the finding counts only when the invariant breaks on what the
simulator really published.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
import ompl  # noqa: F401  -- in the test extra; the stack's planner needs it (a venv without it fails, not skips)

from astaa_deft.orchestration.campaign import signature as sig
from astaa_deft.engine.intercept.testcase import TestCase, parse_testcase
from astaa_deft.orchestration.journal.model import CaseOutcome, Finding
from astaa_deft.orchestration.campaign.originals import broken_on_originals
from astaa_deft.engine.session.check import check_recorded_run
from astaa_deft.engine.spec.loader import load_spec


STACK = Path(__file__).resolve().parent.parent / "examples" / "ompl_stack"
SPEC = STACK / "spec.yaml"


def obstacles_policy(field: str, value: str) -> str:
    return (f'<testcase id="t" seed="1"><description>x</description><policy id="p"><channel>obstacles</channel>'
            f'<set><field path="{field}" value="{value}"/></set></policy></testcase>')


def case(xml: str) -> TestCase:
    """The policy as the campaign holds a test case: an object."""
    return parse_testcase(xml.encode(), "case.xml")


BLOWN_UP = obstacles_policy("obstacles[0].length", "60")  # the parked car reaches back over the ego
NARROWER = obstacles_policy("obstacles[0].width", "1.8")  # 10 cm narrower: changes nothing that matters


def record(tmp: Path, name: str, xml: str, *params: str) -> Path:
    policy, log = tmp / f"{name}.xml", tmp / f"{name}.mcap"
    policy.write_text(xml)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"} | {"PYTHONPATH": str(Path.cwd())}
    res = subprocess.run([sys.executable, "-m", "astaa_deft.cli", "proxy", "--spec", str(SPEC), "--policy", str(policy),
                          "--record", str(log), "--run-dir", str(tmp / name), *params],
                         capture_output=True, text=True, timeout=180, env=env)
    assert res.returncode == 1 and log.is_file(), res.stdout + res.stderr
    return log


def outcome_of(log: Path) -> CaseOutcome:
    """The case's outcome as a campaign worker files it: the run's findings, its log."""
    checked = check_recorded_run(log, SPEC)
    findings = [Finding(invariant=v.invariant, crash=v.crash, module=v.module, channel=v.channel,
                        detail=v.detail) for v in checked.result.violations]
    return CaseOutcome(status="done", verdict=checked.result.verdict.klass, summary=checked.result.verdict.summary,
                       findings=findings, log_path=str(log))


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("self_inflicted")
    blown = record(tmp, "blown", BLOWN_UP, "--param", "sim_time_limit=3")  # the planner never finds a way: 3 s
    # A car pulls in 0.3 m into the ego's front at 5 s: a real contact whatever the rewritten width.
    hit = record(tmp, "hit", NARROWER, "--param", "stopped_car=-0.3", "--param", "goal_x=35")
    return blown, hit


def test_a_collision_only_with_a_rewritten_obstacle_is_self_inflicted_whichever_channel_reports_it(logs):
    blown, _ = logs
    spec = load_spec(SPEC)
    outcome = outcome_of(blown)
    assert {"no_collision", "clearance"} <= {f.invariant for f in outcome.findings}
    judged = sig.without_self_inflicted(outcome, case(BLOWN_UP), spec)
    assert {f.invariant for f in judged.findings} == {"run_end:goal_not_reached"}  # what the SUT really did
    assert "not counted: clearance, no_collision (broke on the rewritten messages only" in judged.summary
    # Online, the same collision is often reported on the ego's message (the other channel it reads): before,
    # the rule looked at that one channel and counted it.
    on_ego = [Finding(invariant="no_collision", crash="Silent", module=None, channel="ego",
                      detail="ego footprint overlaps obstacle 1")]
    judged = sig.without_self_inflicted(
        CaseOutcome(status="done", verdict="Silent", summary="Silent: no_collision", findings=on_ego,
                    log_path=str(blown)), case(BLOWN_UP), spec)
    assert not judged.failed and judged.verdict == "Pass"


def test_a_collision_that_exists_in_the_producers_originals_counts(logs):
    _, hit = logs
    spec = load_spec(SPEC)
    assert broken_on_originals(hit, spec, {"no_collision", "clearance"}, {"obstacles"}) == {"no_collision",
                                                                                             "clearance"}
    judged = sig.without_self_inflicted(outcome_of(hit), case(NARROWER), spec)
    assert judged.failed and "no_collision" in {f.invariant for f in judged.findings}
    assert "counted: clearance, no_collision broke on the producers' originals too" in judged.summary


def test_without_a_readable_log_a_finding_on_a_rewritten_channel_does_not_count(tmp_path, logs):
    spec = load_spec(SPEC)
    assert broken_on_originals(tmp_path / "missing.mcap", spec, {"no_collision"}, {"obstacles"}) is None
    lost = CaseOutcome(status="done", verdict="Silent", summary="Silent: no_collision",
        findings=[Finding(invariant="no_collision", crash="Silent", module=None, channel="ego", detail="overlap")],
        log_path=str(tmp_path / "x.mcap"))
    judged = sig.without_self_inflicted(lost, case(NARROWER), spec)
    assert not judged.failed and "not judged on the originals" in judged.summary
