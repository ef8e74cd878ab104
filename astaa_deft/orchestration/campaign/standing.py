"""Where each bucket stands — its status, severity and rate — and the campaign's headline from them.

A bucket is a *confirmed* bug only when the campaign's control runs made
it one (``Bucket.kind`` BUG: a re-run failed the same way and no unmutated
twin did) and its failure came back (a re-run, or its minimal test case
failing live). A bucket whose re-runs reproduced it 0 times is
*unconfirmed*, never counted as a bug; one whose unmutated twin failed too
or that did not reproduce (*flaky*: the SUT's own flakiness or the
environment), one failing in clean runs (*without mutation*) and one whose
re-runs and twins are still running (*confirming*) are shown apart. So is a
reproduced bucket whose blame is the mutated value itself (*fault alone*:
the fault breaks the invariant through a plant, no module under test
mishandled anything — ``blame.py``): the fault is doing what it says, which is
no bug of the stack, so the headline never counts it among the confirmed bugs.
Buckets rank by status, then severity (the invariant's: critical first), then rate; the headline counts confirmed bugs
by severity and names the most severe. Pure logic over journal rows.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from astaa_deft.engine.monitor.violation import SEVERITIES
from astaa_deft.orchestration.journal.rows import MUTATED_VALUE
from astaa_deft.orchestration.journal.journal import Bucket, Journal
from astaa_deft.model.vocabulary import TextEnum
from astaa_deft.orchestration.journal.model import BucketKind
from astaa_deft.orchestration.journal.rows import CaseRow
from astaa_deft.orchestration.campaign.signature import primary


class BucketStatus(TextEnum):
    """Where a bucket stands, in rank order (confirmed first)."""

    CONFIRMED = "confirmed"
    FAULT_ALONE = "fault alone"
    PENDING = "confirming"
    UNCONFIRMED = "unconfirmed"
    FLAKY = "flaky"
    WITHOUT_MUTATION = "without mutation"


CONFIRMED = BucketStatus.CONFIRMED
FAULT_ALONE = BucketStatus.FAULT_ALONE
FAULT_ALONE_WHY = "the fault alone breaks the invariant; no module under test involved"
UNCONFIRMED = BucketStatus.UNCONFIRMED
FLAKY = BucketStatus.FLAKY
WITHOUT_MUTATION = BucketStatus.WITHOUT_MUTATION
PENDING = BucketStatus.PENDING
STATUS_ORDER = tuple(BucketStatus)


@dataclass(frozen=True, kw_only=True)
class Standing:
    """A bucket with its status, the evidence behind it, its severity and its rate."""

    bucket: Bucket
    status: BucketStatus
    why: str  # the evidence behind the status, one phrase
    severity: str  # of the bucket's finding: low, medium, high, critical
    failures: int  # re-runs (or clean runs) that failed the same way …
    runs: int  # … of these

    @property
    def rate(self) -> float:
        return self.failures / self.runs if self.runs else 0.0

    def describe(self) -> str:
        """One line: bucket, severity, verdict, invariant, where the failure was seen, status and its evidence.

        Where it was seen (the module that died, or whose output broke the
        invariant) is not the module to blame: the blame says that."""
        b = self.bucket
        return (f"{b.bucket} {self.severity} {b.verdict}: {b.invariant}"
                f"{' (seen at ' + b.module + ')' if b.module else ''} — {self.status} ({self.why})")


def bucket_status(bucket: Bucket, failures: int, runs: int, minimised: bool, *,
                  fault_alone: bool = False) -> tuple[BucketStatus, str]:
    """(status, why) of a bucket from the campaign's kind for it, its rate, whether its minimal test case was
    confirmed live and whether its blame is the mutated value itself (``fault_alone``)."""
    twins = f"; unmutated twins {bucket.control_failures}/{bucket.controls} failed" if bucket.controls else ""
    status, why = _status(bucket, failures=failures, runs=runs, minimised=minimised, twins=twins)
    if status == CONFIRMED and fault_alone:
        return FAULT_ALONE, f"{FAULT_ALONE_WHY}; {why}"
    return status, why


def _status(bucket: Bucket, *, failures: int, runs: int, minimised: bool, twins: str) -> tuple[BucketStatus, str]:
    if bucket.without_mutation or bucket.kind == BucketKind.BASELINE:
        return WITHOUT_MUTATION, f"{failures}/{runs} clean runs failed this way"
    if bucket.kind == BucketKind.FLAKY:
        return FLAKY, f"{failures}/{runs} re-runs failed the same way{twins}"
    if bucket.kind == BucketKind.CONFIRMING:
        return PENDING, "its re-runs and unmutated twins are still running"
    if failures:
        return CONFIRMED, f"{failures}/{runs} re-runs failed the same way{twins}"
    if minimised:
        return CONFIRMED, f"its minimal test case failed live{twins}"
    if runs:
        return UNCONFIRMED, f"0/{runs} re-runs failed the same way"
    return UNCONFIRMED, "not re-run"


def rank(standings: Sequence[Standing]) -> list[Standing]:
    """Confirmed first, then by severity (critical first), rate (highest first) and bucket name."""
    def key(s: Standing) -> tuple[int, int, float, str]:
        status = STATUS_ORDER.index(s.status)
        severity = SEVERITIES.index(s.severity) if s.severity in SEVERITIES else -1
        return status, -severity, -s.rate, s.bucket.bucket
    return sorted(standings, key=key)


def standings(journal: Journal) -> list[Standing]:
    """Every bucket not merged into another, ranked (:func:`rank`)."""
    minimised = journal.minimisations()
    blames = journal.blames()
    out = []
    for bucket in journal.buckets(include_merged=False):
        failures, runs = journal.rate(bucket)
        row = minimised.get(bucket.bucket)
        blame = blames.get(bucket.bucket)
        status, why = bucket_status(bucket, failures, runs, row is not None and row.exit_code == 0,
                                    fault_alone=blame is not None and blame.how == MUTATED_VALUE)
        out.append(Standing(bucket=bucket, status=status, why=why, severity=_severity(journal.case(bucket.first_case)),
                            failures=failures, runs=runs))
    return rank(out)


def _severity(row: CaseRow | None) -> str:
    """The severity of the finding a case was filed under ("?" when the journal does not say)."""
    outcome = row.outcome() if row is not None else None
    if outcome is None:
        return "?"
    finding = primary(outcome)
    return finding.severity if finding is not None else "?"


def headline(ranked: Sequence[Standing]) -> str:
    """E.g. "2 confirmed bugs (1 critical, 1 high); 1 where the fault alone breaks the invariant (no module under
    test involved: not counted as bugs); 3 unconfirmed; 1 flaky; 1 failing without mutation"."""
    confirmed = [s for s in ranked if s.status == CONFIRMED]
    if confirmed:
        by_severity = [(sev, sum(1 for s in confirmed if s.severity == sev)) for sev in (*reversed(SEVERITIES), "?")]
        counts = ", ".join(f"{n} {sev}" for sev, n in by_severity if n)
        parts = [f"{len(confirmed)} confirmed bug{'s' if len(confirmed) != 1 else ''} ({counts})"]
    else:
        parts = ["no confirmed bug"]
    others: dict[BucketStatus, int] = {}
    for s in ranked:
        if s.status != CONFIRMED:
            others[s.status] = others.get(s.status, 0) + 1
    for status, n in others.items():
        if status == UNCONFIRMED:
            parts.append(f"{n} unconfirmed (no re-run reproduced {'it' if n == 1 else 'them'}: not counted as bugs)")
        elif status == FAULT_ALONE:
            parts.append(f"{n} where the fault alone breaks the invariant (no module under test involved: "
                         f"not counted as {'a bug' if n == 1 else 'bugs'})")
        elif status == WITHOUT_MUTATION:
            parts.append(f"{n} failing without mutation")
        else:
            parts.append(f"{n} {status}")
    return "; ".join(parts)


def most_severe(ranked: Sequence[Standing]) -> Standing | None:
    """The finding a campaign's verdict names: the top-ranked confirmed bucket, else the top-ranked one."""
    return next((s for s in ranked if s.status == CONFIRMED), ranked[0] if ranked else None)
