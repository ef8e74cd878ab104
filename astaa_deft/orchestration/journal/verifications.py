"""The journal's ``verifications`` table: each bucket checked against a revision of the stack, in order.

Additive: a table of its own in the campaign's journal (created when first
needed), the campaign's tables untouched; an older journal without it reads
as "never verified". One committed row per check.
"""

from __future__ import annotations

import json
import sqlite3
import time
from dataclasses import dataclass

from astaa_deft.io.output_place import OutputError
from astaa_deft.model.errors import InputError, Problem
from astaa_deft.orchestration.journal.journal import Journal
from astaa_deft.orchestration.journal.checked_rows import VERIFICATIONS, checked_columns
from astaa_deft.orchestration.journal.checks import BucketCheck, VerifyStatus

TABLE = """
CREATE TABLE IF NOT EXISTS verifications (
    id INTEGER PRIMARY KEY AUTOINCREMENT, bucket TEXT NOT NULL, revision TEXT NOT NULL, status TEXT NOT NULL,
    failing INTEGER NOT NULL, runs INTEGER NOT NULL,  -- re-runs that failed the bucket's way, of these
    other INTEGER NOT NULL, unobserved INTEGER NOT NULL, twin_failures INTEGER NOT NULL, twins INTEGER NOT NULL,
    module_tests INTEGER,  -- 1: they still fail on the defect, 0: they pass, NULL: none or not run
    detail TEXT NOT NULL, params TEXT NOT NULL, at REAL NOT NULL
);
"""


@dataclass(frozen=True, kw_only=True)
class VerificationRow:
    """One check of a bucket as the journal holds it."""

    bucket: str
    revision: str
    status: VerifyStatus
    failing: int
    runs: int
    twin_failures: int
    twins: int
    module_tests: bool | None
    detail: str
    at: float

    @property
    def stability(self) -> str:
        return f"{self.failing}/{self.runs}"


def _ensure(journal: Journal) -> None:
    try:
        journal.db.executescript(TABLE)
    except sqlite3.OperationalError as exc:
        raise OutputError(Problem(str(journal.path), None, None, f"cannot write the campaign journal: {exc}",
                                  "give a writable campaign directory with free space")) from None


def record(journal: Journal, check: BucketCheck) -> None:
    """Add one check to the journal (a committed row)."""
    _ensure(journal)
    try:
        journal.db.execute(
            "INSERT INTO verifications(bucket, revision, status, failing, runs, other, unobserved, twin_failures,"
            " twins, module_tests, detail, params, at) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
            (check.bucket, check.revision, check.status, check.reruns.same, check.reruns.runs, check.reruns.other,
             check.reruns.unobserved, check.twins.same, check.twins.runs,
             None if check.module_tests is None else int(check.module_tests), check.describe(),
             json.dumps(check.params, sort_keys=True), time.time()))
    except sqlite3.OperationalError as exc:  # full disk, read-only: the journal stays as it was
        raise OutputError(Problem(str(journal.path), None, None, f"cannot write the campaign journal: {exc}",
                                  "free some space (or fix permissions) and verify again")) from None


def reappeared(journal: Journal, bucket: str, case_id: str) -> None:
    """A resumed campaign's case failed the bucket's way after it was verified fixed: the bucket reopens."""
    _ensure(journal)
    try:
        journal.db.execute(
            "INSERT INTO verifications(bucket, revision, status, failing, runs, other, unobserved, twin_failures,"
            " twins, module_tests, detail, params, at) VALUES (?, ?, ?, 1, 1, 0, 0, 0, 0, NULL, ?, '{}', ?)",
            (bucket, CAMPAIGN_REVISION, VerifyStatus.REAPPEARED, f"{bucket} reappeared in campaign case {case_id}",
             time.time()))
    except sqlite3.OperationalError as exc:
        raise OutputError(Problem(str(journal.path), None, None, f"cannot write the campaign journal: {exc}",
                                  "free some space (or fix permissions) and run again with --resume")) from None


CAMPAIGN_REVISION = "(campaign)"  # the revision a resumed campaign's own finding is recorded under


def verifications(journal: Journal) -> list[VerificationRow]:
    """Every check, oldest first ([] for a journal never verified). InputError for a status this version does
    not know (a journal of a newer version)."""
    have = journal.db.execute("SELECT name FROM sqlite_master WHERE type='table' AND name='verifications'").fetchone()
    if have is None:
        return []
    out = []
    file = str(journal.path)
    for row in journal.db.execute("SELECT * FROM verifications ORDER BY at, id"):
        r = checked_columns(file, row, VERIFICATIONS)
        try:
            status = VerifyStatus(r.text("status"))
        except ValueError:
            raise InputError(Problem(file, None, None,
                                     f"verification of {r.text('bucket')[:60]} has an unknown status "
                                     f"'{r.text('status')[:60]}'",
                                     "open this journal with the astaa-deft version that wrote it")) from None
        out.append(VerificationRow(bucket=r.text("bucket"), revision=r.text("revision"), status=status,
                                   failing=r.whole("failing"), runs=r.whole("runs"),
                                   twin_failures=r.whole("twin_failures"), twins=r.whole("twins"),
                                   module_tests=r.flag("module_tests"), detail=r.text("detail"), at=r.number("at")))
    return out
