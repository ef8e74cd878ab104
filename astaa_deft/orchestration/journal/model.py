"""The campaign's model: a planned case, what a run of it gave, a bucket's signature, and the vocabularies.

Pure types with their JSON and text forms; no I/O. They stay in the
orchestration tier (not ``astaa_deft.model``): :meth:`CaseOutcome.keeping`
ranks CRASH classes with the monitors' order (``engine.monitor.verdict``),
which the bottom tier may not import.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace
from typing import Any

from astaa_deft.engine.intercept.testcase import TestCase
from astaa_deft.engine.monitor.verdict import ORDER
from astaa_deft.model.json import JsonObject
from astaa_deft.model.vocabulary import TextEnum
from astaa_deft.model.records import Verdict


class CaseKind(TextEnum):
    """What a planned case is for."""

    BASELINE = "baseline"  # a clean run, no mutation
    MUTATED = "mutated"  # a generated test case
    RERUN = "rerun"  # a bucket's first failure again, for its rate
    CONTROL = "control"  # a failing case's unmutated twin: same params, no test case, same concurrency


class CaseStatus(TextEnum):
    """Where a case is in the journal: planned → running → done (or error); resume puts running back."""

    PLANNED = "planned"
    RUNNING = "running"
    DONE = "done"
    ERROR = "error"  # the run could not start or be judged


class BucketKind(TextEnum):
    """What a bucket is, once its control runs are in: the report tells them apart."""

    BUG = "bug"  # reproduced by a re-run, and the unmutated twin did not fail that way
    FLAKY = "flaky"  # not reproduced, or the unmutated twin failed the same way: flaky SUT or environment
    BASELINE = "baseline"  # fails without any mutation (a clean run, or a case that applied none)
    CONFIRMING = "confirming"  # its re-runs and twins are still running


BASELINE = CaseKind.BASELINE
MUTATED = CaseKind.MUTATED
RERUN = CaseKind.RERUN
CONTROL = CaseKind.CONTROL
CLEAN_KINDS = (BASELINE, CONTROL)  # runs without a test case: run to the scenario's end, timing measured
FINISHED = (CaseStatus.DONE, CaseStatus.ERROR)

BUG = BucketKind.BUG
FLAKY = BucketKind.FLAKY
BASELINE_FINDING = BucketKind.BASELINE
CONFIRMING = BucketKind.CONFIRMING

NO_MUTATION = "(no mutation)"  # the mutation family of a failure in a run that mutated nothing
NO_MODULE = "-"  # a failure key's module when the finding names none
UNKNOWN = "?"  # a failure key's invariant and module when the run has no finding


@dataclass(frozen=True)
class FailureKey:
    """The failure alone (no mutation): CRASH class, invariant, module and, for an error, which error (its
    signature: type and innermost frame); compared with the baseline's."""

    crash: str
    invariant: str
    module: str  # NO_MODULE: the finding named none; UNKNOWN: no finding
    error: str = ""  # the finding's error signature ("KeyError in planner.py:step"); "" when it has none

    def text(self) -> str:
        """The journal's form, ``crash|invariant|module`` (``|error`` after it when the finding names one)."""
        return f"{self.crash}|{self.invariant}|{self.module}" + (f"|{self.error}" if self.error else "")


@dataclass(frozen=True)
class BucketSignature:
    """What groups failures into one bucket: the failure and the family of the mutation that caused it."""

    failure: FailureKey
    family: str  # channel:field:action parts joined by "+", or NO_MUTATION

    def text(self) -> str:
        """The journal's form, ``crash|invariant|module|family``."""
        return f"{self.failure.text()}|{self.family}"

    @classmethod
    def clean(cls, failure: FailureKey) -> BucketSignature:
        """The signature of a failure in a run that mutated nothing."""
        return cls(failure, NO_MUTATION)


@dataclass(frozen=True)
class Timing:
    """When a generated case's windows open: counted from the first message on ``anchor`` (None: from
    the run's start), inside the first ``live`` seconds. The campaign measures both in its baseline runs:
    the anchor is the channel whose first message came last (the whole stack is running then), ``live``
    how long the baseline ran on from there."""

    anchor: str | None
    live: float


@dataclass(frozen=True, kw_only=True)
class PlannedCase:
    """One run to make: everything a worker needs, nothing it must look up."""

    case_id: str  # "b-0001", "c-000042", "r-<bucket>-1", "t-<bucket>-1"
    kind: CaseKind
    number: int  # order in the campaign
    seed: int  # the strategy's seed for this case (the test case's own is inside it)
    params: dict[str, str]
    testcase: TestCase | None  # None: a clean run
    strategy: str = "random"
    parent: str | None = None  # guided: the corpus case this one mutates


@dataclass(frozen=True, kw_only=True)
class Finding:
    """One failure seen in a run: an invariant that broke or a module that died."""

    invariant: str
    crash: str  # CRASH class
    module: str | None
    channel: str | None
    detail: str
    severity: str = "high"  # the invariant's (low … critical); a crash no invariant named: high
    at: float | None = None  # seconds from the run's start to the violation (None: not known)
    signature: str = ""  # which error (type and innermost frame, engine.monitor.error_signature); "" if none


@dataclass(frozen=True)
class ChannelRate:
    """A channel's timing in a clean run: its messages, their rate (1/s) and the longest gap between two (s)."""

    count: int
    rate: float
    max_gap: float


@dataclass(kw_only=True)
class CaseOutcome:
    """What one run of a case gave (JSON-able: it crosses process and machine boundaries)."""

    status: str  # "done", or "error" (the run could not start / be judged)
    verdict: str  # CRASH class of the run (a Verdict's value: "Pass", "Silent", …) or "?" on error
    summary: str
    findings: list[Finding] = field(default_factory=list)
    seconds: float = 0.0
    log_path: str | None = None
    reason: str = ""  # why the run ended: "violation", "horizon", "all modules exited"
    mutations: int = 0
    margins: dict[str, float] = field(default_factory=dict)  # invariant → closest approach (smaller = closer)
    error: str = ""
    # Clean runs: seconds from the modules' launch to each channel's first message (the live stack's timing).
    first_seen: dict[str, float] = field(default_factory=dict)
    # What the run cost: CPU seconds of every process of the run (the case process, its recorder, the modules
    # and what they reaped), the case's wall seconds, the peak summed resident memory (clean runs only).
    cpu: float = 0.0
    cpu_waited: float = 0.0  # CPU seconds its CPU-bound threads waited for a core (clean runs; cost.WantedCpu)
    wall: float = 0.0
    rss_mb: float = 0.0
    # Clean runs: per channel, its message rate (1/s) and its longest gap between two messages (s).
    timing: dict[str, ChannelRate] = field(default_factory=dict)
    # Per invariant: messages (or samples) that broke it — a known baseline finding is judged by these too.
    violating: dict[str, int] = field(default_factory=dict)
    # Clean runs: per module whose exit ended the run, seconds from its last message to its exit (the baseline
    # learns each one's shutdown delay from these).
    shutdowns: dict[str, float] = field(default_factory=dict)

    def to_json(self) -> JsonObject:
        """Its JSON form (the journal's ``outcome`` column, and the pipes from the case workers)."""
        return asdict(self)

    @classmethod
    def from_json(cls, body: JsonObject) -> CaseOutcome:
        """The outcome :meth:`to_json` wrote, by this or an older version (fields it lacks take their
        defaults, fields this version does not know are left out)."""
        fields: dict[str, Any] = dict(body)
        fields["findings"] = [Finding(**f) for f in fields.get("findings", [])]
        fields["timing"] = {channel: ChannelRate(**rate) for channel, rate in fields.get("timing", {}).items()}
        known = cls.__dataclass_fields__
        return cls(**{k: v for k, v in fields.items() if k in known})

    @property
    def failed(self) -> bool:
        return self.status == "done" and self.verdict != Verdict.PASS

    def keeping(self, kept: list[Finding], note: str) -> CaseOutcome:
        """This outcome with only the ``kept`` findings (``note`` says why the rest do not count): its verdict
        the most severe kept finding's class, Pass when none is left."""
        if not kept:
            return replace(self, verdict=Verdict.PASS, findings=[], summary=f"{Verdict.PASS}{note}")
        klass = next(c for c in ORDER if any(f.crash == c for f in kept) or c is Verdict.PASS)
        return replace(self, verdict=klass if klass is not Verdict.PASS else self.verdict, findings=kept,
                       summary=self.summary + note)


def testcase_text(testcase: TestCase | None) -> str | None:
    """A test case's stored form (the journal's column, the payload's key); None for a clean run."""
    return testcase.to_xml().decode() if testcase is not None else None
