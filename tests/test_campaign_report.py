"""The campaign report's content, from a journal written the way a campaign writes it (real SQLite)."""

from __future__ import annotations

import html
from pathlib import Path

import pytest

from astaa_deft.model.errors import InputError

from astaa_deft.engine.intercept.testcase import parse_testcase
from astaa_deft.orchestration.journal.journal import Journal, Minimisation, NewBucket
from astaa_deft.orchestration.journal.model import (
    BASELINE, MUTATED, BucketSignature, CaseOutcome, FailureKey, Finding, PlannedCase,
)
from astaa_deft.orchestration.campaign.report import write_report

XML = '<testcase id="tc-{n}" seed="{n}"><description/><policy id="p"><channel>routing</channel>' \
      '<set><field path="speed_limit" value="dict:float.nan"/></set></policy></testcase>'


def _case(journal: Journal, out: Path, case_id: str, kind: str, n: int, verdict: str, reason: str,
          bucket: str | None = None, finding: Finding | None = None) -> None:
    journal.plan(PlannedCase(case_id=case_id, kind=kind, number=n, seed=1, params={"scenario": "lane_follow"},
                             testcase=None if kind == BASELINE else parse_testcase(XML.format(n=n).encode()),
                             strategy="random"))
    journal.started(case_id)
    log = out / "cases" / case_id / "run.mcap"
    outcome = CaseOutcome(status="done", verdict=verdict, summary=f"{verdict}: …",
                          findings=[finding] if finding else [], seconds=3.0, log_path=str(log), reason=reason,
                          margins={"planned_speed": 0.2 / n})
    journal.finished(case_id, outcome, signature=_signature("sig") if bucket else None, bucket=bucket)


def _signature(family: str) -> BucketSignature:
    return BucketSignature(FailureKey("Silent", "x", "-"), family)


def test_report_shows_buckets_culprits_tests_merges_and_how_runs_ended(tmp_path: Path):
    out = tmp_path / "campaign"
    journal = Journal(out)
    try:
        journal.set_meta(spec="/x/demo_av.yaml", seed=1, strategy="random", params={}, horizon=8.0)
        speed = Finding(invariant="planned_speed", crash="Silent", module="planning", channel="trajectory",
                        detail="v 20 > 15")
        _case(journal, out, "b-0001", BASELINE, 1, "Pass", "goal reached")
        _case(journal, out, "c-000001", MUTATED, 1, "Silent", "violation", "B001", speed)
        _case(journal, out, "c-000002", MUTATED, 2, "Silent", "violation", "B002", speed)
        _case(journal, out, "c-000003", MUTATED, 3, "Pass", "goal reached")
        _case(journal, out, "b-0002", BASELINE, 2, "Restart", "violation", "B003",
              Finding(invariant="control_alive", crash="Restart", module="control", channel="command", detail="silent"))
        journal.add_bucket(NewBucket(name="B001", signature=_signature("routing:speed_limit:set+routing:x:set"),
                                     verdict="Silent", invariant="planned_speed", module="planning",
                                     first_case="c-000001", without_mutation=False, after_cases=2))
        journal.add_bucket(NewBucket(name="B002", signature=_signature("routing:speed_limit:set"), verdict="Silent",
                                     invariant="speed_limit", module="planning", first_case="c-000002",
                                     without_mutation=False, after_cases=3))
        journal.add_bucket(NewBucket(name="B003", signature=_signature("(no mutation)"), verdict="Restart",
                                     invariant="control_alive", module="control", first_case="b-0002",
                                     without_mutation=True, after_cases=5))
        journal.minimised(Minimisation(bucket="B001", status="minimised", exit_code=0,
                                       minimal_xml="<testcase id='minimal-1'/>",
                                       culprit="routing:speed_limit = dict:float.nan",
                                       out_dir=str(out / "minimised" / "B001"), tests_dir=str(out / "tests" / "B001"),
                                       seconds=12.0, detail=""))
        journal.minimised(Minimisation(bucket="B002", status="minimised", exit_code=0,
                                       minimal_xml="<testcase id='minimal-2'/>",
                                       culprit="routing:speed_limit = dict:float.nan",
                                       out_dir=str(out / "minimised" / "B002"),
                                       tests_dir=str(out / "tests" / "B002-replay"), seconds=12.0, detail=""))
        journal.merge_bucket("B002", "B001")
    finally:
        journal.close()
    page = write_report(out).read_text()
    text = html.unescape(page)
    assert "<title>astaa-deft campaign: demo_av</title>" in page
    # B001 confirmed by its minimisation (no re-run ran), B002 merged into it, B003 a clean-run failure
    assert "1 confirmed bug (1 high); 1 failing without mutation" in text
    # Where a failure was seen is not whom to blame: the headline and the Buckets column say "seen at".
    assert "B001 high Silent: planned_speed (seen at planning) — confirmed (its minimal test case failed live)" in text
    assert "seen at</th>" in page and "not the module to blame (see Blame)" in page
    assert "violation 3, goal reached 2" in text  # how runs ended
    assert "routing:speed_limit = dict:float.nan" in text
    assert "<div>routing:speed_limit:set</div><div>routing:x:set</div>" in page  # one family part a line
    assert "merged into B001" in text and "without mutation" in text
    assert "<testcase id='minimal-1'/>" in text and "minimal test case (XML)" in text
    assert "first failing test case (not minimised)" not in text  # every mutated bucket was minimised
    assert "href='tests/B001'" in page and "fail on the culprit; <code>pytest tests/B001</code>" in page
    assert "DeFT replay of the failing run" in text
    assert "href='cases/c-000001/run.mcap'" in page
    assert page.count("data:image/png;base64,") == 4
    assert "Traceback" not in page


EVIL = "<img src=x onerror=alert(2)>"


def test_every_cell_is_escaped_whatever_its_declared_type(tmp_path: Path):
    """Markup in any text cell shows as text; SQLite keeps whatever was written, so a numeric column may hold
    markup too: that journal is damaged input (exit 2), never a page."""
    import sqlite3

    out = tmp_path / "campaign"
    journal = Journal(out)
    try:
        journal.set_meta(spec=f"/x/{EVIL}.yaml", seed=1, strategy=EVIL, params={EVIL: [EVIL]}, horizon=8.0)
        speed = Finding(invariant="planned_speed", crash="Silent", module="planning", channel="trajectory",
                        detail="v 20 > 15")
        _case(journal, out, "c-000001", MUTATED, 1, "Silent", EVIL, "B001", speed)
        journal.add_bucket(NewBucket(name="B001", signature=_signature(f"{EVIL}+x"), verdict="Silent", invariant=EVIL,
                                     module=EVIL, first_case="c-000001", without_mutation=False, after_cases=2))
        journal.minimised(Minimisation(bucket="B001", status=EVIL, exit_code=0, minimal_xml=EVIL, culprit=EVIL,
                                       out_dir=str(out / EVIL), tests_dir=str(out / EVIL), seconds=1.0, detail=EVIL))
        journal.module_tests_checked("B001", EVIL, None, EVIL)
    finally:
        journal.close()
    db = sqlite3.connect(out / "journal.sqlite")
    db.execute("UPDATE buckets SET verdict=?", (EVIL,))
    db.execute("UPDATE cases SET log_path=?, testcase_xml=?", (EVIL, EVIL))
    db.commit()
    db.close()
    page = write_report(out).read_text()
    assert "<img src" not in page and "onerror=alert(2)>" not in page
    assert "&lt;img src=x onerror=alert(2)&gt;" in page  # shown, as text
    db = sqlite3.connect(out / "journal.sqlite")
    db.execute("UPDATE buckets SET cases=?", (EVIL,))
    db.commit()
    db.close()
    with pytest.raises(InputError) as caught:
        write_report(out)
    assert "buckets[B001].cases" in str(caught.value) and "whole number" in str(caught.value)
