"""The campaign's journal: one SQLite file, the source of truth for resume, status and report.

Every state change is its own committed transaction (WAL mode), so a
Ctrl-C or a kill -9 loses at most the cases that were running: a case is
``planned`` → ``running`` → ``done``; on resume every ``running`` case goes
back to ``planned`` and runs again.
"""

from __future__ import annotations

import json
import sqlite3
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from collections.abc import Iterator

from astaa_deft.model.errors import InputError, Problem
from astaa_deft.io.output_place import OutputError
from astaa_deft.orchestration.campaign.model import BASELINE_FINDING, BUG, CONTROL, RERUN, CaseOutcome, PlannedCase

FILE_NAME = "journal.sqlite"

# Columns added since the first journals: added to an older journal when it is opened (resume, report).
ADDED_COLUMNS = {
    "cases": (("cpu", "REAL"), ("load", "REAL"), ("at_once", "INTEGER")),
    "buckets": (("kind", "TEXT NOT NULL DEFAULT 'bug'"), ("controls", "INTEGER NOT NULL DEFAULT 0"),
                ("control_failures", "INTEGER NOT NULL DEFAULT 0")),
    "minimisations": (("started_at", "REAL"), ("finished_at", "REAL")),
}

SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS cases (
    case_id TEXT PRIMARY KEY, kind TEXT NOT NULL, number INTEGER NOT NULL, seed INTEGER NOT NULL,
    params TEXT NOT NULL, testcase_xml TEXT, strategy TEXT NOT NULL, parent TEXT,
    status TEXT NOT NULL DEFAULT 'planned',  -- planned, running, done, error
    verdict TEXT, summary TEXT, signature TEXT, failure_key TEXT, bucket TEXT, outcome TEXT,
    planned_at REAL, started_at REAL, finished_at REAL, seconds REAL, log_path TEXT, worker TEXT,
    cpu REAL, load REAL, at_once INTEGER  -- the run's CPU s, the 1-min load and the runs at once when it ended
);
CREATE INDEX IF NOT EXISTS cases_status ON cases(status);
CREATE TABLE IF NOT EXISTS buckets (
    bucket TEXT PRIMARY KEY, signature TEXT NOT NULL, verdict TEXT NOT NULL, invariant TEXT NOT NULL,
    module TEXT, family TEXT NOT NULL, first_case TEXT NOT NULL, without_mutation INTEGER NOT NULL,
    cases INTEGER NOT NULL DEFAULT 1, reruns INTEGER NOT NULL DEFAULT 0, rerun_failures INTEGER NOT NULL DEFAULT 0,
    merged_into TEXT, created_at REAL NOT NULL, created_after_cases INTEGER NOT NULL,
    kind TEXT NOT NULL DEFAULT 'bug',  -- bug, flaky, baseline, confirming (model.py)
    controls INTEGER NOT NULL DEFAULT 0, control_failures INTEGER NOT NULL DEFAULT 0  -- unmutated twins
);
CREATE TABLE IF NOT EXISTS notes (time REAL NOT NULL, topic TEXT NOT NULL, text TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS minimisations (
    bucket TEXT PRIMARY KEY, status TEXT NOT NULL, exit_code INTEGER, minimal_xml TEXT, culprit TEXT,
    out_dir TEXT, tests_dir TEXT, seconds REAL, detail TEXT,
    started_at REAL, finished_at REAL  -- status 'running' from the start to the end
);
CREATE TABLE IF NOT EXISTS module_tests (  -- a bucket's module tests, run once on its defect
    bucket TEXT PRIMARY KEY, tests_dir TEXT NOT NULL,
    fails_on_defect INTEGER,  -- 1: they fail as they should, 0: they do not, NULL: they could not run
    detail TEXT NOT NULL
);
"""


@dataclass(frozen=True)
class Bucket:
    bucket: str
    signature: str
    verdict: str
    invariant: str
    module: str | None
    family: str
    first_case: str
    without_mutation: bool
    cases: int
    reruns: int
    rerun_failures: int
    merged_into: str | None
    created_at: float
    created_after_cases: int
    kind: str = BUG  # BUG, FLAKY, BASELINE_FINDING or CONFIRMING (model.py)
    controls: int = 0  # unmutated twins run
    control_failures: int = 0  # of those, how many failed the same way

    @property
    def rate(self) -> float | None:
        return self.rerun_failures / self.reruns if self.reruns else None

    @property
    def is_bug(self) -> bool:
        """Confirmed: reproduced, and its unmutated twins did not fail that way."""
        return self.kind == BUG


class Journal:
    def __init__(self, directory: Path):
        self.path = directory / FILE_NAME
        try:
            directory.mkdir(parents=True, exist_ok=True)
            self.db = sqlite3.connect(self.path, timeout=30.0, isolation_level=None, check_same_thread=False)
            self.db.execute("PRAGMA journal_mode=WAL")
            self.db.execute("PRAGMA synchronous=NORMAL")
            self.db.executescript(SCHEMA)
            self._add_columns()
        except (sqlite3.OperationalError, OSError) as exc:  # read-only, full, over the size limit
            raise OutputError(Problem(str(self.path), None, None, f"cannot open the campaign journal: {exc}",
                                      "give a writable campaign directory (-o) with free space")) from None
        except sqlite3.Error as exc:  # not a database, or a damaged one
            raise InputError(Problem(str(self.path), None, None, f"cannot read the campaign journal: {exc}",
                                     "move the damaged journal away, or give another campaign directory (-o)")) \
                from None
        self.db.row_factory = sqlite3.Row

    def close(self) -> None:
        self.db.close()

    def _add_columns(self) -> None:
        for table, columns in ADDED_COLUMNS.items():
            have = {r[1] for r in self.db.execute(f"PRAGMA table_info({table})")}
            for name, decl in columns:
                if name not in have:
                    self.db.execute(f"ALTER TABLE {table} ADD COLUMN {name} {decl}")
        # a journal from before bucket kinds: its clean-run buckets are baseline findings
        self.db.execute("UPDATE buckets SET kind=? WHERE without_mutation=1 AND kind=?", (BASELINE_FINDING, BUG))

    def _write(self, sql: str, args: tuple = ()) -> None:
        try:
            self.db.execute(sql, args)
        except sqlite3.OperationalError as exc:  # full disk, read-only file: the journal stays as it was
            raise OutputError(Problem(str(self.path), None, None, f"cannot write the campaign journal: {exc}",
                                     "free some space (or fix permissions) and run again with --resume")) from None

    # -- meta ---------------------------------------------------------------
    def set_meta(self, **values: Any) -> None:
        for key, value in values.items():
            self._write("INSERT OR REPLACE INTO meta(key, value) VALUES (?, ?)", (key, json.dumps(value)))

    def meta(self) -> dict[str, Any]:
        return {r["key"]: json.loads(r["value"]) for r in self.db.execute("SELECT key, value FROM meta")}

    # -- cases --------------------------------------------------------------
    def plan(self, case: PlannedCase) -> None:
        self._write("INSERT OR IGNORE INTO cases(case_id, kind, number, seed, params, testcase_xml, strategy, parent,"
                    " planned_at) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
                    (case.case_id, case.kind, case.number, case.seed, json.dumps(case.params, sort_keys=True),
                     case.testcase_xml, case.strategy, case.parent, time.time()))

    def started(self, case_id: str, worker: str = "") -> None:
        self._write("UPDATE cases SET status='running', started_at=?, worker=? WHERE case_id=?",
                    (time.time(), worker, case_id))

    def finished(self, case_id: str, outcome: CaseOutcome, signature: str | None, failure_key: str | None,
                 bucket: str | None) -> None:
        self._write("UPDATE cases SET status=?, verdict=?, summary=?, signature=?, failure_key=?, bucket=?,"
                    " outcome=?, finished_at=?, seconds=?, log_path=? WHERE case_id=?",
                    ("done" if outcome.status == "done" else "error", outcome.verdict, outcome.summary, signature,
                     failure_key, bucket, json.dumps(outcome.to_json(), default=str), time.time(), outcome.seconds,
                     outcome.log_path, case_id))

    def file_case(self, case_id: str, signature: str, failure_key: str, bucket: str) -> None:
        """File a finished case into a bucket decided after it finished (baseline runs, once calibrated)."""
        self._write("UPDATE cases SET signature=?, failure_key=?, bucket=? WHERE case_id=?",
                    (signature, failure_key, bucket, case_id))

    def cost(self, case_id: str, cpu: float, load: float, at_once: int) -> None:
        """What a finished case cost and how loaded the machine was when it ended."""
        self._write("UPDATE cases SET cpu=?, load=?, at_once=? WHERE case_id=?", (cpu, load, at_once, case_id))

    def requeue_running(self) -> int:
        """On resume: cases that were in flight run again (their partial results are not trusted)."""
        cur = self.db.execute("UPDATE cases SET status='planned', started_at=NULL WHERE status='running'")
        return cur.rowcount

    def pending(self, kind: str | None = None) -> list[PlannedCase]:
        sql = "SELECT * FROM cases WHERE status='planned'" + (" AND kind=?" if kind else "") + " ORDER BY number"
        return [_planned(r) for r in self.db.execute(sql, (kind,) if kind else ())]

    def cases(self, kind: str | None = None) -> list[sqlite3.Row]:
        sql = "SELECT * FROM cases" + (" WHERE kind=?" if kind else "") + " ORDER BY number"
        return list(self.db.execute(sql, (kind,) if kind else ()))

    def case(self, case_id: str) -> sqlite3.Row | None:
        return self.db.execute("SELECT * FROM cases WHERE case_id=?", (case_id,)).fetchone()

    def planned(self, case_id: str) -> sqlite3.Row:
        """A case the campaign planned itself (a KeyError if the journal lost it: a bug, not bad input)."""
        row = self.case(case_id)
        if row is None:
            raise KeyError(f"case {case_id} is not in the journal")
        return row

    def outcome(self, row: sqlite3.Row) -> CaseOutcome | None:
        return CaseOutcome.from_json(json.loads(row["outcome"])) if row["outcome"] else None

    def counts(self) -> dict[str, int]:
        return {f"{r['kind']}:{r['status']}": r["n"] for r in
                self.db.execute("SELECT kind, status, COUNT(*) AS n FROM cases GROUP BY kind, status")}

    def max_number(self, kind: str) -> int:
        row = self.db.execute("SELECT MAX(number) FROM cases WHERE kind=?", (kind,)).fetchone()
        return int(row[0] or 0)

    # -- buckets ------------------------------------------------------------
    def add_bucket(self, bucket: str, signature: str, verdict: str, invariant: str, module: str | None,
                   family: str, first_case: str, without_mutation: bool, after_cases: int, *,
                   kind: str = BUG) -> None:
        self._write("INSERT OR IGNORE INTO buckets(bucket, signature, verdict, invariant, module, family, first_case,"
                    " without_mutation, created_at, created_after_cases, kind)"
                    " VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                    (bucket, signature, verdict, invariant, module, family, first_case, int(without_mutation),
                     time.time(), after_cases, kind))

    def bucket_kind(self, bucket: str, kind: str) -> None:
        self._write("UPDATE buckets SET kind=? WHERE bucket=?", (kind, bucket))

    def bucket_control(self, bucket: str, failed: bool) -> None:
        self._write("UPDATE buckets SET controls = controls + 1, control_failures = control_failures + ?"
                    " WHERE bucket=?", (int(failed), bucket))

    def unfinished(self, parent: str) -> int:
        """Re-runs and control runs of a bucket not finished yet."""
        return int(self.db.execute("SELECT COUNT(*) FROM cases WHERE parent=? AND kind IN (?, ?)"
                                   " AND status IN ('planned', 'running')", (parent, RERUN, CONTROL)).fetchone()[0])

    def bucket_hit(self, bucket: str) -> None:
        self._write("UPDATE buckets SET cases = cases + 1 WHERE bucket=?", (bucket,))

    def bucket_rerun(self, bucket: str, failed: bool) -> None:
        self._write("UPDATE buckets SET reruns = reruns + 1, rerun_failures = rerun_failures + ? WHERE bucket=?",
                    (int(failed), bucket))

    def merge_bucket(self, bucket: str, into: str) -> None:
        self._write("UPDATE buckets SET merged_into=? WHERE bucket=?", (into, bucket))

    def bucket(self, name: str) -> Bucket:
        return next(b for b in self.buckets() if b.bucket == name)

    def buckets(self, include_merged: bool = True) -> list[Bucket]:
        rows = self.db.execute("SELECT * FROM buckets ORDER BY created_at")
        out = [Bucket(**{**dict(r), "without_mutation": bool(r["without_mutation"])}) for r in rows]
        return [b for b in out if include_merged or b.merged_into is None]

    def rate(self, bucket: Bucket) -> tuple[int, int]:
        """(failures, runs) behind a bucket's rate: its re-runs, or the baseline runs for a clean-run failure."""
        if bucket.without_mutation:
            rows = [r for r in self.cases("baseline") if r["status"] == "done"]
            return sum(1 for r in rows if r["signature"] == bucket.signature), len(rows)
        return bucket.rerun_failures, bucket.reruns

    def bucket_by_signature(self, signature: str) -> Bucket | None:
        return next((b for b in self.buckets() if b.signature == signature), None)

    # -- minimisations ------------------------------------------------------
    def minimisation_started(self, bucket: str) -> None:
        self._write("INSERT OR REPLACE INTO minimisations(bucket, status, started_at) VALUES (?, 'running', ?)",
                    (bucket, time.time()))

    def requeue_minimisations(self) -> int:
        """On resume: minimisations that were running start again."""
        return self.db.execute("DELETE FROM minimisations WHERE status='running'").rowcount

    def minimised(self, bucket: str, status: str, exit_code: int | None, minimal_xml: str | None,
                  culprit: str | None, out_dir: str | None, tests_dir: str | None, seconds: float,
                  detail: str) -> None:
        started = self.db.execute("SELECT started_at FROM minimisations WHERE bucket=?", (bucket,)).fetchone()
        self._write("INSERT OR REPLACE INTO minimisations(bucket, status, exit_code, minimal_xml, culprit, out_dir,"
                    " tests_dir, seconds, detail, started_at, finished_at) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                    (bucket, status, exit_code, minimal_xml, culprit, out_dir, tests_dir, seconds, detail,
                     started[0] if started else None, time.time()))

    def minimisations(self) -> dict[str, sqlite3.Row]:
        return {r["bucket"]: r for r in self.db.execute("SELECT * FROM minimisations")}

    # -- notes: what the campaign decided about itself (runs at once, back-offs), with why -------------
    def note(self, topic: str, text: str) -> None:
        self._write("INSERT INTO notes(time, topic, text) VALUES (?, ?, ?)", (time.time(), topic, text))

    def notes(self, topic: str | None = None) -> list[sqlite3.Row]:
        sql = "SELECT * FROM notes" + (" WHERE topic=?" if topic else "") + " ORDER BY time"
        return list(self.db.execute(sql, (topic,) if topic else ()))

    # -- module tests -------------------------------------------------------
    def module_tests_checked(self, bucket: str, tests_dir: str, fails_on_defect: bool | None, detail: str) -> None:
        """Whether a bucket's module tests fail on its defect (None: they could not run), and why."""
        self._write("INSERT OR REPLACE INTO module_tests VALUES (?, ?, ?, ?)",
                    (bucket, tests_dir, None if fails_on_defect is None else int(fails_on_defect), detail))

    def module_tests(self) -> dict[str, sqlite3.Row]:
        return {r["bucket"]: r for r in self.db.execute("SELECT * FROM module_tests")}


def _planned(row: sqlite3.Row) -> PlannedCase:
    return PlannedCase(row["case_id"], row["kind"], row["number"], row["seed"], json.loads(row["params"]),
                       row["testcase_xml"], row["strategy"], row["parent"])


def open_existing(directory: Path) -> Journal:
    if not (directory / FILE_NAME).is_file():
        raise InputError(Problem(str(directory), None, None, "no campaign journal here",
                                 f"give a directory written by 'astaa-deft fuzz -o {directory}'"))
    return Journal(directory)


def iter_done(journal: Journal) -> Iterator[sqlite3.Row]:
    yield from journal.db.execute("SELECT * FROM cases WHERE status IN ('done','error') ORDER BY finished_at")
