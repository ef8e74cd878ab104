"""The campaign's journal: one SQLite file, the source of truth for resume, status and report.

Every state change is its own committed transaction (WAL mode), so a
Ctrl-C or a kill -9 loses at most the cases that were running: a case is
``planned`` → ``running`` → ``done``; on resume every ``running`` case goes
back to ``planned`` and runs again. Reading yields typed rows (``rows.py``);
an older journal gains the columns added since when it is opened.

Thread safety: one connection shared by the campaign's threads
(``check_same_thread=False``); each statement is atomic, SQLite serialises them.
"""

from __future__ import annotations

import json
import sqlite3
import time
from pathlib import Path

from astaa_deft.io.output_place import OutputError, link_refusal
from astaa_deft.model.errors import InputError, Problem
from astaa_deft.orchestration.journal.model import (
    BASELINE, BASELINE_FINDING, BUG, CONTROL, RERUN, BucketKind, BucketSignature, CaseKind, CaseOutcome, CaseStatus,
    FailureKey, PlannedCase,
)
from astaa_deft.orchestration.journal.checked_rows import (
    FIX, MAX_BUCKETS, blame_row, bucket_row, case_row, check_columns, meta_of, minimisation_row, module_tests_row,
    note_row,
)
from astaa_deft.orchestration.journal.model import testcase_text
from astaa_deft.orchestration.journal.rows import (
    BlameRow, Bucket, CampaignMeta, CaseRow, Minimisation, MinimisationRow, ModuleTestsRow, NewBucket, NoteRow,
)

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
CREATE TABLE IF NOT EXISTS blames (  -- a confirmed bucket's module to blame (blame.py) and its root-cause identity
    bucket TEXT PRIMARY KEY, module TEXT, output TEXT, how TEXT NOT NULL, chain TEXT NOT NULL, detail TEXT NOT NULL,
    twins INTEGER NOT NULL, identity TEXT,  -- NULL: no identity (no module to blame)
    replay TEXT  -- how a replay of the module to blame confirmed it (NULL: none did)
);
CREATE TABLE IF NOT EXISTS module_tests (  -- a bucket's module tests, run once on its defect
    bucket TEXT PRIMARY KEY, tests_dir TEXT NOT NULL,
    fails_on_defect INTEGER,  -- 1: they fail as they should, 0: they do not, NULL: they could not run
    detail TEXT NOT NULL
);
"""


class Journal:
    """The journal in ``directory`` (created if missing). OutputError when it cannot be opened for writing,
    InputError when the file is not a journal (damaged)."""

    def __init__(self, directory: Path) -> None:
        self.path = directory / FILE_NAME
        for own in (self.path, self.path.with_name(FILE_NAME + "-wal"), self.path.with_name(FILE_NAME + "-shm")):
            if own.is_symlink():  # SQLite would write where it points: never through a link
                raise link_refusal(own, "-o")
        try:
            directory.mkdir(parents=True, exist_ok=True)
            self.db = sqlite3.connect(self.path, timeout=30.0, isolation_level=None, check_same_thread=False)
            self.db.execute("PRAGMA journal_mode=WAL")
            self.db.execute("PRAGMA synchronous=NORMAL")
            check_columns(self.db, str(self.path), SCHEMA, ADDED_COLUMNS)  # damaged: InputError, not OutputError
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

    def _write(self, sql: str, args: tuple[object, ...] = ()) -> None:
        try:
            self.db.execute(sql, args)
        except sqlite3.OperationalError as exc:  # full disk, read-only file: the journal stays as it was
            raise OutputError(Problem(str(self.path), None, None, f"cannot write the campaign journal: {exc}",
                                     "free some space (or fix permissions) and run again with --resume")) from None

    # -- meta ---------------------------------------------------------------
    def set_meta(self, **values: object) -> None:
        """Store campaign settings: key (a field of :class:`CampaignMeta`) → a value ``json.dumps`` takes."""
        for key, value in values.items():
            self._write("INSERT OR REPLACE INTO meta(key, value) VALUES (?, ?)", (key, json.dumps(value)))

    def meta(self) -> CampaignMeta:
        return meta_of(str(self.path), self.db.execute("SELECT key, value FROM meta"))

    # -- cases --------------------------------------------------------------
    def plan(self, case: PlannedCase) -> None:
        self._write("INSERT OR IGNORE INTO cases(case_id, kind, number, seed, params, testcase_xml, strategy, parent,"
                    " planned_at) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
                    (case.case_id, case.kind, case.number, case.seed, json.dumps(case.params, sort_keys=True),
                     testcase_text(case.testcase), case.strategy, case.parent, time.time()))

    def started(self, case_id: str, worker: str = "") -> None:
        self._write("UPDATE cases SET status='running', started_at=?, worker=? WHERE case_id=?",
                    (time.time(), worker, case_id))

    def finished(self, case_id: str, outcome: CaseOutcome, *, signature: BucketSignature | None = None,
                 failure: FailureKey | None = None, bucket: str | None = None) -> None:
        """A case's run is over: its outcome, and for a failing case its signature, its failure key (default:
        the signature's; a failing baseline run has a key and no signature until it is filed) and bucket."""
        status = CaseStatus.DONE if outcome.status == CaseStatus.DONE else CaseStatus.ERROR
        if failure is None and signature is not None:
            failure = signature.failure
        self._write("UPDATE cases SET status=?, verdict=?, summary=?, signature=?, failure_key=?, bucket=?,"
                    " outcome=?, finished_at=?, seconds=?, log_path=? WHERE case_id=?",
                    (status, outcome.verdict, outcome.summary, signature.text() if signature is not None else None,
                     failure.text() if failure is not None else None, bucket,
                     json.dumps(outcome.to_json(), default=str), time.time(), outcome.seconds, outcome.log_path,
                     case_id))

    def file_case(self, case_id: str, signature: BucketSignature, bucket: str) -> None:
        """File a finished case into a bucket decided after it finished (baseline runs, once calibrated)."""
        self._write("UPDATE cases SET signature=?, failure_key=?, bucket=? WHERE case_id=?",
                    (signature.text(), signature.failure.text(), bucket, case_id))

    def cost(self, case_id: str, cpu: float, load: float, at_once: int) -> None:
        """What a finished case cost and how loaded the machine was when it ended."""
        self._write("UPDATE cases SET cpu=?, load=?, at_once=? WHERE case_id=?", (cpu, load, at_once, case_id))

    def requeue_running(self) -> int:
        """On resume: cases that were in flight run again (their partial results are not trusted)."""
        cur = self.db.execute("UPDATE cases SET status='planned', started_at=NULL WHERE status='running'")
        return cur.rowcount

    def pending(self, kind: CaseKind | None = None) -> list[CaseRow]:
        """The planned cases not started yet (of ``kind``), in order (``CaseRow.planned``: what a worker runs)."""
        sql = "SELECT * FROM cases WHERE status='planned'" + (" AND kind=?" if kind else "") + " ORDER BY number"
        return [case_row(str(self.path), r) for r in self.db.execute(sql, (kind,) if kind else ())]

    def cases(self, kind: CaseKind | None = None) -> list[CaseRow]:
        """Every case (of ``kind``), in order."""
        sql = "SELECT * FROM cases" + (" WHERE kind=?" if kind else "") + " ORDER BY number"
        return [case_row(str(self.path), r) for r in self.db.execute(sql, (kind,) if kind else ())]

    def case(self, case_id: str) -> CaseRow | None:
        row = self.db.execute("SELECT * FROM cases WHERE case_id=?", (case_id,)).fetchone()
        return case_row(str(self.path), row) if row is not None else None

    def planned(self, case_id: str) -> CaseRow:
        """A case the campaign planned itself (a KeyError if the journal lost it: a bug, not bad input)."""
        row = self.case(case_id)
        if row is None:
            raise KeyError(f"case {case_id} is not in the journal")
        return row

    def outcome(self, row: CaseRow) -> CaseOutcome | None:
        """What the case's run gave (None: not finished)."""
        return row.outcome()

    def finished_count(self) -> int:
        """Cases done or in error."""
        return int(self.db.execute("SELECT COUNT(*) FROM cases WHERE status IN ('done', 'error')").fetchone()[0])

    def counts(self) -> dict[str, int]:
        return {f"{r['kind']}:{r['status']}": r["n"] for r in
                self.db.execute("SELECT kind, status, COUNT(*) AS n FROM cases GROUP BY kind, status")}

    def max_number(self, kind: CaseKind) -> int:
        row = self.db.execute("SELECT MAX(number) FROM cases WHERE kind=?", (kind,)).fetchone()
        return int(row[0] or 0)

    # -- buckets ------------------------------------------------------------
    def add_bucket(self, new: NewBucket) -> None:
        """Open a bucket (a bucket of that name already there stays as it is)."""
        self._write("INSERT OR IGNORE INTO buckets(bucket, signature, verdict, invariant, module, family, first_case,"
                    " without_mutation, created_at, created_after_cases, kind)"
                    " VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                    (new.name, new.signature.text(), new.verdict, new.invariant, new.module, new.signature.family,
                     new.first_case, int(new.without_mutation), time.time(), new.after_cases, new.kind))

    def bucket_kind(self, bucket: str, kind: BucketKind) -> None:
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
        row = self.db.execute("SELECT * FROM buckets WHERE bucket=?", (name,)).fetchone()
        if row is None:
            raise KeyError(f"bucket {name} is not in the journal")  # one the campaign filed itself: a bug
        return self._bucket(row)

    def buckets(self, include_merged: bool = True) -> list[Bucket]:
        """Every bucket in the order they were opened (``include_merged`` False: those not merged into another).
        InputError for a bucket kind this version does not know (a journal of a newer version), or more
        buckets than one campaign files (``MAX_BUCKETS``: a damaged journal, refused at once, not read)."""
        count = int(self.db.execute("SELECT COUNT(*) FROM buckets").fetchone()[0])
        if count > MAX_BUCKETS:
            raise InputError(Problem(str(self.path), None, None,
                                     f"the journal holds {count:,} buckets (a campaign files at most "
                                     f"{MAX_BUCKETS:,}): it is damaged, or not a campaign journal", FIX))
        out = [self._bucket(r) for r in self.db.execute("SELECT * FROM buckets ORDER BY created_at")]
        return [b for b in out if include_merged or b.merged_into is None]

    def _bucket(self, row: sqlite3.Row) -> Bucket:
        return bucket_row(str(self.path), row)  # schema-checked: InputError naming the field

    def rate(self, bucket: Bucket) -> tuple[int, int]:
        """(failures, runs) behind a bucket's rate: its re-runs, or the baseline runs for a clean-run failure."""
        if bucket.without_mutation:
            rows = [r for r in self.cases(BASELINE) if r.status == CaseStatus.DONE]
            return sum(1 for r in rows if r.signature == bucket.signature), len(rows)
        return bucket.rerun_failures, bucket.reruns

    def bucket_by_signature(self, signature: BucketSignature) -> Bucket | None:
        text = signature.text()
        return next((b for b in self.buckets() if b.signature == text), None)

    # -- minimisations ------------------------------------------------------
    def minimisation_started(self, bucket: str) -> None:
        self._write("INSERT OR REPLACE INTO minimisations(bucket, status, started_at) VALUES (?, 'running', ?)",
                    (bucket, time.time()))

    def requeue_minimisations(self) -> int:
        """On resume: minimisations that were running start again."""
        return self.db.execute("DELETE FROM minimisations WHERE status='running'").rowcount

    def minimised(self, result: Minimisation) -> None:
        """A bucket's minimisation is over (or replaced): what it gave; its start time stays."""
        started = self.db.execute("SELECT started_at FROM minimisations WHERE bucket=?", (result.bucket,)).fetchone()
        self._write("INSERT OR REPLACE INTO minimisations(bucket, status, exit_code, minimal_xml, culprit, out_dir,"
                    " tests_dir, seconds, detail, started_at, finished_at) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                    (result.bucket, result.status, result.exit_code, result.minimal_xml, result.culprit,
                     result.out_dir, result.tests_dir, result.seconds, result.detail,
                     started[0] if started else None, time.time()))

    def minimisations(self) -> dict[str, MinimisationRow]:
        """Bucket name → its minimisation (running or over)."""
        return {r["bucket"]: minimisation_row(str(self.path), r)
                for r in self.db.execute("SELECT * FROM minimisations")}

    # -- notes: what the campaign decided about itself (runs at once, back-offs), with why -------------
    def note(self, topic: str, text: str) -> None:
        self._write("INSERT INTO notes(time, topic, text) VALUES (?, ?, ?)", (time.time(), topic, text))

    def notes(self, topic: str | None = None) -> list[NoteRow]:
        sql = "SELECT * FROM notes" + (" WHERE topic=?" if topic else "") + " ORDER BY time"
        return [note_row(str(self.path), r) for r in self.db.execute(sql, (topic,) if topic else ())]

    # -- blame --------------------------------------------------------------
    def blamed(self, row: BlameRow) -> None:
        """A confirmed bucket's module to blame, the chain that says why, and its root-cause identity."""
        self._write("INSERT OR REPLACE INTO blames VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
                    (row.bucket, row.module, row.output, row.how, row.chain, row.detail, row.twins, row.identity,
                     row.replay))

    def blames(self) -> dict[str, BlameRow]:
        """Bucket name → its blame."""
        return {row.bucket: row for row in (blame_row(str(self.path), r)
                                            for r in self.db.execute("SELECT * FROM blames"))}

    # -- module tests -------------------------------------------------------
    def module_tests_checked(self, bucket: str, tests_dir: str, fails_on_defect: bool | None, detail: str) -> None:
        """Whether a bucket's module tests fail on its defect (None: they could not run), and why."""
        self._write("INSERT OR REPLACE INTO module_tests VALUES (?, ?, ?, ?)",
                    (bucket, tests_dir, None if fails_on_defect is None else int(fails_on_defect), detail))

    def module_tests(self) -> dict[str, ModuleTestsRow]:
        """Bucket name → whether its module tests fail on its defect."""
        return {r["bucket"]: module_tests_row(str(self.path), r) for r in self.db.execute("SELECT * FROM module_tests")}


def open_existing(directory: Path) -> Journal:
    """The journal a campaign wrote in ``directory``; InputError when there is none."""
    if not (directory / FILE_NAME).is_file():
        raise InputError(Problem(str(directory), None, None, "no campaign journal here",
                                 f"give a directory written by 'astaa-deft fuzz -o {directory}'"))
    return Journal(directory)


__all__ = ["Bucket", "CaseRow", "FILE_NAME", "Journal", "Minimisation", "MinimisationRow", "NewBucket",
           "open_existing"]
