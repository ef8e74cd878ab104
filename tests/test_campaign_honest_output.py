"""Honest campaign output: confirmed bugs apart, ranked by severity, the most severe named.

Journals are real SQLite files written the way a campaign writes them; the
verdict is the monitors' own function over real violation records.
"""

from __future__ import annotations

import html
from pathlib import Path

import pytest

from astaa_deft.orchestration.campaign import signature as sig
from astaa_deft.orchestration.journal.journal import Journal, Minimisation, NewBucket
from astaa_deft.orchestration.journal.model import (
    MUTATED, BucketSignature, CaseOutcome, FailureKey, Finding, PlannedCase,
)
from astaa_deft.orchestration.campaign.report import write_report
from astaa_deft.orchestration.campaign.standing import (CONFIRMED, UNCONFIRMED, WITHOUT_MUTATION, headline, most_severe,
                                          standings)
from astaa_deft.engine.monitor.verdict import run_verdict
from astaa_deft.engine.monitor.violation import Violation

CLEARANCE = Finding(invariant="clearance", crash="Silent", module=None, channel="ego",
                    detail="overlaps by 0.1 m with a 0.3 m margin", severity="medium")
COLLISION = Finding(invariant="no_collision", crash="Silent", module=None, channel="ego",
                    detail="overlaps obstacle 2 by 0.05 m", severity="critical")
CRASH = Finding(invariant="(module exit)", crash="Abort", module="planning", channel=None, detail="killed by SIGABRT",
                severity="high")


def test_a_run_is_filed_under_its_most_severe_finding_not_its_first():
    outcome = CaseOutcome(status="done", verdict="Silent", summary="…", findings=[CLEARANCE, COLLISION])
    assert sig.primary(outcome) == COLLISION
    assert sig.failure_key(outcome).text() == "Silent|no_collision|-"
    # same severity: the worse CRASH class, then the earlier
    assert sig.primary(CaseOutcome(status="done", verdict="Abort", summary="…",
                                   findings=[CLEARANCE, CRASH, replace_severity(CRASH)])) == CRASH


def replace_severity(finding: Finding) -> Finding:
    return Finding(invariant=finding.invariant + "2", crash="Silent", module=finding.module, channel=finding.channel,
                   detail=finding.detail, severity="high")


def test_the_verdict_line_names_the_most_severe_finding_and_still_says_which_came_first():
    clearance = Violation(invariant="clearance", invariant_kind="collision", severity="medium", time_ns=1_000,
                          channel="ego", seq=1, message=None, detail="overlaps by 0.1 m", crash="Silent")
    contact = Violation(invariant="no_collision", invariant_kind="collision", severity="critical", time_ns=2_000,
                        channel="ego", seq=2, message=None, detail="overlaps by 0.05 m", crash="Silent")
    verdict = run_verdict([clearance, contact], [], ["planning", "simulator"])
    assert verdict.klass == "Silent"
    assert verdict.summary.startswith("Silent: no_collision: overlaps by 0.05 m (2 findings)")
    assert verdict.summary.endswith("first: clearance: overlaps by 0.1 m")
    assert verdict.first == clearance


def _bucket(journal: Journal, name: str, finding: Finding, *, reruns: int = 0, failures: int = 0,
            without_mutation: bool = False) -> None:
    case = f"c-{name}"
    journal.plan(PlannedCase(case_id=case, kind=MUTATED, number=int(name[1:]), seed=1, params={}, testcase=None,
                             strategy="random"))
    signature = BucketSignature(FailureKey(finding.crash, finding.invariant, finding.module or "-"), "ego:x:set")
    journal.finished(case, CaseOutcome(status="done", verdict=finding.crash, summary="…", findings=[finding]),
                     signature=signature, bucket=name)
    journal.add_bucket(NewBucket(name=name, signature=signature, verdict=finding.crash, invariant=finding.invariant,
                                 module=finding.module, first_case=case, without_mutation=without_mutation,
                                 after_cases=1))
    for k in range(reruns):
        journal.bucket_rerun(name, k < failures)


def test_buckets_rank_confirmed_first_by_severity_then_rate_and_unconfirmed_ones_are_no_bugs(tmp_path: Path):
    out = tmp_path / "campaign"
    journal = Journal(out)
    try:
        journal.set_meta(spec="/x/ompl_stack.yaml", seed=1, strategy="random", params={}, horizon=20.0)
        _bucket(journal, "B001", CLEARANCE, reruns=2, failures=2)  # first found, least severe
        _bucket(journal, "B002",
            Finding(invariant="plans_flow", crash="Restart", module="planning", channel="plan", detail="silent 5 s",
                    severity="high"),
            reruns=2, failures=0)  # load: never came back
        _bucket(journal, "B003", CRASH, reruns=2, failures=1)
        _bucket(journal, "B004", COLLISION, reruns=2, failures=2)
        _bucket(journal, "B005",
            Finding(invariant="plans_flow", crash="Restart", module="planning", channel="plan", detail="silent",
                    severity="high"),
            without_mutation=True)
        _bucket(journal, "B006",
            Finding(invariant="planner_errors", crash="Silent", module="planning", channel=None, detail="Traceback",
                    severity="high"),
            reruns=2, failures=2)
        journal.module_tests_checked("B003", str(out / "tests" / "B003-replay"), True,
                                     "the planner's replay raises CollisionCheckerFault")
        journal.module_tests_checked("B006", str(out / "tests" / "B006-replay"), False, "they pass on the defect")
        journal.minimised(Minimisation(bucket="B003", status="minimised", exit_code=0, minimal_xml=None,
                                       culprit="obstacles:obstacles[].length = -1", out_dir=None,
                                       tests_dir=str(out / "tests" / "B003-replay"), seconds=30.0, detail=""))
        journal.minimised(Minimisation(bucket="B006", status="minimised", exit_code=0, minimal_xml=None,
                                       culprit="ego:heading = nan", out_dir=None,
                                       tests_dir=str(out / "tests" / "B006-replay"), seconds=30.0, detail=""))
        ranked = standings(journal)
        assert [(s.bucket.bucket, s.status, s.severity) for s in ranked] == [
            ("B004", CONFIRMED, "critical"), ("B006", CONFIRMED, "high"), ("B003", CONFIRMED, "high"),
            ("B001", CONFIRMED, "medium"), ("B002", UNCONFIRMED, "high"), ("B005", WITHOUT_MUTATION, "high")]
        assert ranked[4].why == "0/2 re-runs failed the same way"
        assert headline(ranked) == ("4 confirmed bugs (1 critical, 2 high, 1 medium); 1 unconfirmed (no re-run"
                                    " reproduced it: not counted as bugs); 1 failing without mutation")
        top = most_severe(ranked)
        assert top is not None and top.describe() == ("B004 critical Silent: no_collision — confirmed"
                                                      " (2/2 re-runs failed the same way)")
    finally:
        journal.close()
    text = html.unescape(write_report(out).read_text())
    assert "4 confirmed bugs (1 critical, 2 high, 1 medium)" in text and "bug bucket" not in text
    assert "most severe: B004 critical Silent: no_collision" in text.replace("<b>", "")
    assert text.index("id='B004'") < text.index("id='B006'") < text.index("id='B003'") < text.index("id='B001'") \
        < text.index("id='B002'") < text.index("id='B005'")
    assert "fail on the defect</span> <span class='muted'>(the planner's replay raises CollisionCheckerFault)" in text
    assert "do not fail on the defect</span> <span class='muted'>(they pass on the defect)" in text


def test_a_campaign_of_unconfirmed_buckets_finds_no_bug(tmp_path: Path):
    journal = Journal(tmp_path / "c")
    try:
        _bucket(journal, "B001", COLLISION, reruns=2, failures=0)
        _bucket(journal, "B002", CRASH)  # --reruns 0 and not minimised
        ranked = standings(journal)
        assert [s.status for s in ranked] == [UNCONFIRMED, UNCONFIRMED]
        assert ranked[1].why == "not re-run"
        assert headline(ranked).startswith("no confirmed bug; 2 unconfirmed")
        top = most_severe(ranked)
        assert top is not None and top.bucket.bucket == "B001"  # named, with its status
    finally:
        journal.close()


def test_a_bucket_where_the_fault_alone_breaks_the_invariant_is_listed_apart_and_never_a_confirmed_bug(tmp_path):
    """The demo's case: an acceleration held at its declared maximum pushes the simulator (a plant) over the speed
    limit; blame finds no module under test that departed from its twins, so the fault did it alone."""
    from astaa_deft.orchestration.journal.rows import MUTATED_VALUE
    from astaa_deft.orchestration.journal.rows import BlameRow
    from astaa_deft.orchestration.campaign.standing import FAULT_ALONE

    out = tmp_path / "campaign"
    journal = Journal(out)
    try:
        journal.set_meta(spec="/x/demo_av.yaml", seed=1, strategy="random", params={}, horizon=6.0, minimise=False)
        speeding = Finding(invariant="speed_limit", crash="Silent", module=None, channel="ego",
                           detail="12.4 m/s over 11.1", severity="critical")
        _bucket(journal, "B001", speeding, reruns=1, failures=1)
        _bucket(journal, "B002", CRASH, reruns=1, failures=1)
        journal.blamed(BlameRow(bucket="B001", module=None, output="ego", how=MUTATED_VALUE,
                                chain="command → sim → ego → speed_limit", detail="ego departed first", twins=1,
                                identity=None))
        ranked = standings(journal)
        assert [(s.bucket.bucket, s.status) for s in ranked] == [("B002", CONFIRMED), ("B001", FAULT_ALONE)]
        assert "the fault alone breaks the invariant; no module under test involved" in ranked[1].why
        line = headline(ranked)
        assert line.startswith("1 confirmed bug (1 high); 1 where the fault alone breaks the invariant"), line
        assert "critical" not in line  # the critical finding is the fault's, not the stack's
        top = most_severe(ranked)
        assert top is not None and top.bucket.bucket == "B002"
    finally:
        journal.close()
    text = html.unescape(write_report(out).read_text())
    assert "1 confirmed bug (1 high)" in text
    assert "not minimised: minimisation was off for this campaign" in text
    assert text.count("not minimised</span>") == 0  # every "not minimised" says why


@pytest.mark.slow
def test_the_demos_headline_counts_no_bucket_where_the_fault_alone_breaks_the_invariant(tmp_path: Path):
    """The demo's own campaign step, as `astaa-deft demo` runs it: whatever its runs found, the headline's
    confirmed bugs are the reproduced buckets whose blame names a module (or none), never the mutated value."""
    import subprocess
    import sys

    from astaa_deft.orchestration.journal.rows import MUTATED_VALUE
    from astaa_deft.orchestration.journal.journal import open_existing

    out = tmp_path / "campaign"
    code = ("import sys; from pathlib import Path; from astaa_deft.demo.bundled import demo_spec_path; "
            "from astaa_deft.orchestration.campaign.demo_step import campaign_step; "
            f"campaign_step(demo_spec_path(), Path({str(out)!r}))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stdout + done.stderr
    [line] = [x for x in done.stdout.splitlines() if " runs in " in x and "bucket(s)" in x]
    journal = open_existing(out)
    try:
        ranked = standings(journal)
        blames = journal.blames()
    finally:
        journal.close()
    alone = [s for s in ranked if (b := blames.get(s.bucket.bucket)) is not None and b.how == MUTATED_VALUE
             and s.failures]
    counted = [s for s in ranked if s.status == CONFIRMED]
    assert not {s.bucket.bucket for s in alone} & {s.bucket.bucket for s in counted}
    bugs = f"{len(counted)} confirmed bug{'s' if len(counted) != 1 else ''}" if counted else "no confirmed bug"
    assert f"bucket(s): {bugs}" in line, line
    if alone:
        assert "where the fault alone breaks the invariant" in line, line
    print(line)
