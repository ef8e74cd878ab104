"""What verifying one bucket means, and how its runs classify it. Pure types and logic, no I/O.

A bucket's minimal test case (or, not minimised, the test case of its first
failure) runs N times beside N unmutated twins. A run *fails the bucket's
way* when it breaks the bucket's invariant in the bucket's module (first or
later in its run: the campaign's rule for re-runs and twins), *another way*
when it fails otherwise. Then, in this order:

* a twin failed the bucket's way: **flaky** — the unmutated stack fails so
  too, the test case cannot be blamed (the campaign's rule);
* a run failed the bucket's way: **still failing** (stability k/N);
* a run failed another way: **changed** — unless the unmutated twins broke
  the same invariants in the same modules (the machine's load, the stack's
  own flakiness: that run is not counted as failing);
* a run was not observed to its end: **not observed** — never "fixed" on
  runs nobody saw;
* else **fixed** (0/N fail).
"""

from __future__ import annotations

from dataclasses import dataclass

from astaa_deft.model.vocabulary import TextEnum
from astaa_deft.orchestration.journal.model import NO_MODULE, CaseOutcome


class VerifyStatus(TextEnum):
    """Where a bucket stands against the stack as it is now."""

    FIXED = "fixed"
    STILL_FAILING = "still failing"
    CHANGED = "changed"  # fails, but another way
    FLAKY = "flaky"  # its unmutated twins fail that way too
    NOT_OBSERVED = "not observed"  # some run was not observed to its end, and none failed
    REAPPEARED = "reappeared"  # a resumed campaign's case failed the bucket's way after it was verified fixed


FAILING_STATUSES = frozenset({VerifyStatus.STILL_FAILING, VerifyStatus.CHANGED, VerifyStatus.FLAKY,
                              VerifyStatus.REAPPEARED})


@dataclass(frozen=True)
class FailureWay:
    """The failure a bucket was filed under: the invariant and the module (None: the finding named none)."""

    invariant: str
    module: str | None

    def shown_by(self, outcome: CaseOutcome) -> bool:
        """Whether the run broke this invariant in this module, first or later in its run."""
        module = self.module or NO_MODULE
        return outcome.failed and any(f.invariant == self.invariant and (f.module or NO_MODULE) == module
                                      for f in outcome.findings)


@dataclass(frozen=True, kw_only=True)
class Tally:
    """Runs of one kind (re-runs of the test case, or unmutated twins) and how they ended."""

    runs: int = 0
    same: int = 0  # failed the bucket's way
    other: int = 0  # failed another way
    unobserved: int = 0  # not observed to their end (errors)
    other_how: str = ""  # the first other failure, one line

    @classmethod
    def of(cls, outcomes: list[CaseOutcome], way: FailureWay,
           background: frozenset[tuple[str, str]] = frozenset()) -> Tally:
        """Count ``outcomes``; a run failing another way only with findings in ``background`` (what the
        unmutated twins broke too: the machine's load, the stack's own flakiness) is not counted as failing."""
        same = [o for o in outcomes if way.shown_by(o)]
        other = [o for o in outcomes if o.failed and not way.shown_by(o) and not failure_keys(o) <= background]
        return cls(runs=len(outcomes), same=len(same), other=len(other),
                   unobserved=sum(1 for o in outcomes if o.status != "done"),
                   other_how=other[0].summary[:200] if other else "")


def failure_keys(outcome: CaseOutcome) -> frozenset[tuple[str, str]]:
    """(invariant, module) of each of a run's findings."""
    return frozenset((f.invariant, f.module or NO_MODULE) for f in outcome.findings) if outcome.failed \
        else frozenset()


def classify(reruns: Tally, twins: Tally) -> VerifyStatus:
    """The bucket's status from its re-runs and its twins (module doc)."""
    if twins.same:
        return VerifyStatus.FLAKY
    if reruns.same:
        return VerifyStatus.STILL_FAILING
    if reruns.other:
        return VerifyStatus.CHANGED
    if reruns.unobserved or not reruns.runs:
        return VerifyStatus.NOT_OBSERVED
    return VerifyStatus.FIXED


@dataclass(frozen=True, kw_only=True)
class BucketCheck:
    """One bucket verified against one revision of the stack."""

    bucket: str
    revision: str
    status: VerifyStatus
    reruns: Tally
    twins: Tally
    module_tests: bool | None  # True: they still fail on the defect; False: they pass; None: none, or not run
    module_detail: str
    params: dict[str, str]
    minimal: bool  # the minimal test case ran (False: the first failing case's, not minimised)

    @property
    def stability(self) -> str:
        """k/N: re-runs that failed the bucket's way."""
        return f"{self.reruns.same}/{self.reruns.runs}"

    def describe(self) -> str:
        """One line: bucket, status, stability, twins, module tests."""
        parts = [f"{self.bucket} {self.status}: {self.stability} run(s) failed its way"]
        if self.reruns.other:
            parts.append(f"{self.reruns.other} another way ({self.reruns.other_how})")
        if self.reruns.unobserved:
            parts.append(f"{self.reruns.unobserved} not observed to the end")
        parts.append(f"unmutated twins {self.twins.same}/{self.twins.runs} failed its way")
        if self.module_tests is not None:
            parts.append("module tests still fail on it" if self.module_tests else "module tests pass")
        elif self.module_detail:
            parts.append(f"module tests: {self.module_detail}")
        if not self.minimal:
            parts.append("(the first failing test case: not minimised)")
        return "; ".join(parts)
