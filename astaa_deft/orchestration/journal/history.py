"""Each bucket's history from its verifications: found on, fixed on, reopened. Pure logic over journal rows.

A bucket is *found* by the campaign (or, in the checks, first seen failing
on a revision); it is *fixed on* the first revision of its latest unbroken
run of "fixed" checks; it is *reopened* on each revision where it fails
again after a "fixed" check (a verify, or a resumed campaign's case).
"Not observed" checks say nothing either way.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from astaa_deft.orchestration.journal.checks import FAILING_STATUSES, VerifyStatus
from astaa_deft.orchestration.journal.verifications import VerificationRow


@dataclass(frozen=True, kw_only=True)
class BucketHistory:
    bucket: str
    latest: VerificationRow | None  # the newest check (None: never verified)
    failing_on: tuple[str, ...]  # revisions it failed on, in order
    fixed_on: str | None  # where it became fixed and stayed so (None: not fixed now)
    reopened_on: tuple[str, ...]  # revisions where it failed again after a "fixed" check

    @property
    def fixed_now(self) -> bool:
        return self.fixed_on is not None

    def describe(self) -> str:
        """One phrase: e.g. "fixed on v1.2 (reopened on v1.1-3-gabc, fixed again)"."""
        if self.latest is None:
            return "never verified"
        parts = [f"found by the campaign{'; failing on ' + ', '.join(self.failing_on) if self.failing_on else ''}"]
        if self.reopened_on:
            parts.append(f"reopened on {', '.join(self.reopened_on)}")
        if self.fixed_on is not None:
            parts.append(f"fixed on {self.fixed_on}")
        else:
            parts.append(f"now {self.latest.status} on {self.latest.revision} ({self.latest.stability})")
        return "; ".join(parts)


def history(bucket: str, rows: Sequence[VerificationRow]) -> BucketHistory:
    """The history of ``bucket`` from every check (oldest first; other buckets' rows are ignored)."""
    mine = [r for r in rows if r.bucket == bucket and r.status != VerifyStatus.NOT_OBSERVED]
    failing: list[str] = []
    reopened: list[str] = []
    fixed_on: str | None = None
    was_fixed = False
    for row in mine:
        if row.status == VerifyStatus.FIXED:
            if fixed_on is None:
                fixed_on = row.revision
            was_fixed = True
        elif row.status in FAILING_STATUSES:
            if row.revision not in failing:
                failing.append(row.revision)
            if was_fixed:
                reopened.append(row.revision)
            fixed_on, was_fixed = None, False
    latest = next((r for r in reversed(rows) if r.bucket == bucket), None)
    return BucketHistory(bucket=bucket, latest=latest, failing_on=tuple(failing), fixed_on=fixed_on,
                         reopened_on=tuple(reopened))


def histories(rows: Sequence[VerificationRow]) -> dict[str, BucketHistory]:
    """Bucket → its history, for every bucket checked at least once."""
    return {name: history(name, rows) for name in dict.fromkeys(r.bucket for r in rows)}


def fixed_buckets(rows: Sequence[VerificationRow]) -> set[str]:
    """The buckets whose latest check (not counting "not observed") says fixed."""
    return {name for name, seen in histories(rows).items() if seen.fixed_now}
