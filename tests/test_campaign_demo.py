"""`astaa-deft fuzz` end to end on the demo stack: real subprocesses, real Zenoh, real SQLite."""

from __future__ import annotations

import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

from astaa_deft.cli.commands.demo import demo_spec_path
from astaa_deft.engine.monitor import check_log
from astaa_deft.engine.spec.loader import load_spec
from astaa_deft.io.log.reader import read_log
from stack_timing import overtaken_before_read, unexplained

# Seed 25: generated case 1 empties trajectory.points (seeded defect 3: control crashes); case 2 (a non-finite
# steering value the simulator ignores, or — its window fitted to the baseline's live phase, which load moves —
# another harmless field) is no bug.
FINDING_SEED = "25"
ATTEMPTS = 3  # campaigns whose empty trajectory a loaded machine's next one may overtake before control reads it


def fuzz(*args: str, timeout: float = 240) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "astaa_deft.cli", "fuzz", *args], capture_output=True, text=True,
                          timeout=timeout)


def rows(out: Path, sql: str) -> list[tuple]:
    db = sqlite3.connect(out / "journal.sqlite")
    try:
        return db.execute(sql).fetchall()
    finally:
        db.close()


def test_campaign_finds_buckets_reruns_and_reports(tmp_path: Path):
    spec = load_spec(demo_spec_path())
    for attempt in range(ATTEMPTS):
        out = tmp_path / f"campaign{attempt}"
        done = fuzz("--spec", str(demo_spec_path()), "-o", str(out), "--cases", "2", "--seed", FINDING_SEED,
                    "--horizon", "6", "--workers", "3", "--baseline", "1", "--reruns", "1", "--no-minimise",
                    "--no-module-level")  # the live cases alone (tests/test_module_level.py: the module level)
        # Control reads the newest trajectory whenever a localization comes: on a loaded machine the next
        # trajectory can come first, or control stall until it has, and the empty one is never read (the case
        # or its re-run then passes, rightly). Only a run whose own log shows that may be tried again.
        verdicts = dict(rows(out, "SELECT case_id, verdict FROM cases"))
        if not any(verdicts.get(case) == "Pass" and overtaken_before_read(
                read_log(out / "cases" / case / "run.mcap"), spec, read_on="localization", answered_on="command")
                for case in ("c-000001", "r-B001-1")):
            break
    assert done.returncode == 1, done.stdout + done.stderr  # a finding
    cases = dict(rows(out, "SELECT case_id, status FROM cases"))
    # Another bucket only from a deadline a loaded machine made the stack miss (its own stamps show it), which its
    # re-run does not repeat: never a bug.
    others = rows(out, "SELECT bucket, kind, first_case FROM buckets WHERE bucket != 'B001'")
    for other, other_kind, first_case in others:
        other_log = read_log(out / "cases" / first_case / "run.mcap")
        assert other_kind != "bug" and unexplained(check_log(other_log, spec).violations, other_log, spec) == [], (
            other, other_kind)
    # the failing case re-run once and its unmutated twin (same params, no test case) once
    assert cases == {"b-0001": "done", "c-000001": "done", "c-000002": "done", "r-B001-1": "done",
                     "t-B001-1": "done", **{f"{run}-{other}-1": "done" for other, _, _ in others for run in "rt"}}
    (bucket, verdict, invariant, module, family, first, without, reruns, fails, kind, controls, control_fails), = rows(
        out, "SELECT bucket, verdict, invariant, module, family, first_case, without_mutation, reruns,"
             " rerun_failures, kind, controls, control_failures FROM buckets WHERE bucket = 'B001'")
    assert (bucket, verdict, module, family, first, without) == ("B001", "Abort", "control", "trajectory:points:set",
                                                                 "c-000001", 0)
    # Seeded defect 3 is deterministic (control indexes the empty trajectory): the re-run reproduces it, and
    # the unmutated twin does not, so the bucket is a bug.
    assert (reruns, fails) == (1, 1)
    assert (controls, control_fails) == (1, 0)  # the clean demo does not crash control
    assert kind == "bug"
    # each case its own run dir and log
    assert (out / "cases" / "c-000001" / "run.mcap").is_file() and (out / "cases" / "c-000002" / "run.mcap").is_file()
    # the report is the journal's: the bucket, its culprit family, the minimal/generated XML, the log link, plots
    page = (out / "report.html").read_text()
    assert "B001" in page and "Abort" in page and "trajectory:points:set" in page
    assert "cases/c-000001/run.mcap" in page and "dict:array.empty" in page
    assert page.count("data:image/png;base64,") == 4
    status = fuzz("--status", "-o", str(out))
    assert status.returncode == 0 and "B001" in status.stdout and "Abort" in status.stdout
    (out / "report.html").unlink()
    regen = subprocess.run([sys.executable, "-m", "astaa_deft.cli", "report", str(out)], capture_output=True,
                           text=True, timeout=120)
    assert regen.returncode == 0 and "B001" in (out / "report.html").read_text()


def test_kill_9_then_resume_loses_no_finished_case(tmp_path: Path):
    out = tmp_path / "campaign"
    args = ["--spec", str(demo_spec_path()), "-o", str(out), "--cases", "4", "--seed", "5", "--horizon", "3",
            "--workers", "2", "--baseline", "1", "--no-minimise", "--params", "defects=off", "--no-module-level"]
    proc = subprocess.Popen([sys.executable, "-m", "astaa_deft.cli", "fuzz", *args], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True)
    finished_before: list[tuple] = []
    deadline = time.monotonic() + 120
    try:
        while time.monotonic() < deadline:
            time.sleep(0.1)
            if (out / "journal.sqlite").exists():
                try:
                    finished_before = rows(out, "SELECT case_id, verdict, finished_at FROM cases WHERE kind='mutated'"
                                                " AND status='done'")
                except sqlite3.OperationalError:  # the file is there, its tables not yet: look again
                    continue
                if finished_before:
                    break
        assert finished_before, "no case finished before the kill"
        os.kill(proc.pid, signal.SIGKILL)  # the campaign process only; its case processes die with it
        proc.wait(timeout=10)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    done = fuzz("--spec", str(demo_spec_path()), "-o", str(out), "--resume", "--horizon", "3")
    # Defects off: no bug. A loaded machine can make a case's planner miss its deadline; the campaign files
    # that as failing without mutation (its own clean runs and twins say so), never as a bug — exit 1 then,
    # as for any bucket (docs/campaigns.md).
    buckets = rows(out, "SELECT bucket, signature, kind, without_mutation FROM buckets")
    assert done.returncode == (1 if buckets else 0), done.stdout + done.stderr
    assert [b for b in buckets if b[2] == "bug" and not b[3]] == [], done.stdout
    after = rows(out, "SELECT case_id, verdict, finished_at FROM cases WHERE kind='mutated'")
    assert len(after) == 4
    not_passed = rows(out, "SELECT c.case_id FROM cases c LEFT JOIN buckets b ON c.bucket = b.bucket "
                           "WHERE c.kind='mutated' AND c.verdict != 'Pass' "
                           "AND (b.bucket IS NULL OR (b.kind = 'bug' AND b.without_mutation = 0))")
    assert not_passed == [], done.stdout  # every case passed, or failed as its bucket says it does unmutated
    for case in finished_before:  # finished then: the same record now, not re-run
        assert case in after
