"""What the campaign's journal holds, as typed rows: a case, a bucket, a minimisation, module tests, a note,
the campaign's settings (meta). Pure types; ``journal.py`` reads and writes them.

Text columns keep their stored form (a bucket's ``signature`` is the text
:meth:`BucketSignature.text` wrote, or whatever an older journal holds);
vocabularies (case kind and status, bucket kind) are read into their enums.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

from astaa_deft.engine.intercept.testcase import TestCase
from astaa_deft.model.json import JsonObject
from astaa_deft.orchestration.journal.model import (
    BUG, BucketKind, BucketSignature, CaseKind, CaseOutcome, CaseStatus, PlannedCase, Timing,
)

# A blame's ``how`` when a plant carried the mutated value on (no module under test is to blame), and the root
# cause such a blame names. Here, not in ``campaign/blame.py``: the journal's blame rows name it too.
MUTATED_VALUE = "mutated value"
THE_MUTATED_VALUE = "the mutated value itself"


def root_cause_of(module: str | None, how: str) -> str | None:
    """The root cause a blame names, as bucket identity and the user see it: the module to blame, "the mutated
    value itself" when a plant carried the value on, None when nothing says."""
    if module is not None:
        return module
    return THE_MUTATED_VALUE if how == MUTATED_VALUE else None


@dataclass(frozen=True, kw_only=True)
class CaseRow:
    """One case of the journal: what was planned, where it is, and what its run gave (once finished)."""

    case_id: str
    kind: CaseKind
    number: int
    seed: int
    params: dict[str, str]
    testcase_xml: str | None
    strategy: str
    parent: str | None
    status: CaseStatus
    verdict: str | None = None
    summary: str | None = None
    signature: str | None = None  # BucketSignature.text() of a failing case
    failure_key: str | None = None  # FailureKey.text() of a failing case
    bucket: str | None = None
    outcome_json: str | None = None  # CaseOutcome's JSON text (None: not finished)
    planned_at: float | None = None
    started_at: float | None = None
    finished_at: float | None = None
    seconds: float | None = None
    log_path: str | None = None
    worker: str | None = None
    cpu: float | None = None  # the run's CPU seconds …
    load: float | None = None  # … the 1-min load average when it ended …
    at_once: int | None = None  # … and the runs at once then

    @property
    def finished(self) -> bool:
        return self.status in (CaseStatus.DONE, CaseStatus.ERROR)

    @property
    def params_key(self) -> str:
        """Its params as one comparable text (the journal's form): cases of the same param values share it."""
        return json.dumps(self.params, sort_keys=True)

    def outcome(self) -> CaseOutcome | None:
        """What its run gave (None: not finished)."""
        return CaseOutcome.from_json(json.loads(self.outcome_json)) if self.outcome_json else None

    def planned(self, testcase: TestCase | None) -> PlannedCase:
        """The case as it was planned (what a worker runs), with its test case read back from
        :attr:`testcase_xml` (``payload.read_testcase``: the row keeps the stored text)."""
        return PlannedCase(case_id=self.case_id, kind=self.kind, number=self.number, seed=self.seed, params=self.params,
                           testcase=testcase, strategy=self.strategy, parent=self.parent)


@dataclass(frozen=True, kw_only=True)
class NewBucket:
    """A bucket as the campaign opens it, on the failure of ``first_case`` (after ``after_cases`` cases)."""

    name: str
    signature: BucketSignature
    verdict: str
    invariant: str
    module: str | None
    first_case: str
    without_mutation: bool
    after_cases: int
    kind: BucketKind = BUG


@dataclass(frozen=True, kw_only=True)
class Bucket:
    """A bucket as the journal holds it: its failure, its counts, and what the campaign made of it."""

    bucket: str
    signature: str  # BucketSignature.text(), as stored
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
    kind: BucketKind = BUG
    controls: int = 0  # unmutated twins run
    control_failures: int = 0  # of those, how many failed the same way

    @property
    def rate(self) -> float | None:
        return self.rerun_failures / self.reruns if self.reruns else None

    @property
    def is_bug(self) -> bool:
        """Confirmed: reproduced, and its unmutated twins did not fail that way."""
        return self.kind == BUG


@dataclass(frozen=True, kw_only=True)
class Minimisation:
    """What minimising a bucket gave (``status``: "minimised", "not reproduced", "error", "running", or a
    strategy's own, e.g. decictor's "module tests (fail)")."""

    bucket: str
    status: str
    exit_code: int | None
    minimal_xml: str | None
    culprit: str | None  # what the minimal test case does, e.g. "routing:speed_limit = dict:float.nan"
    out_dir: str | None
    tests_dir: str | None
    seconds: float | None
    detail: str | None


@dataclass(frozen=True, kw_only=True)
class MinimisationRow(Minimisation):
    """A minimisation as the journal holds it: with when it started and ended."""

    started_at: float | None = None
    finished_at: float | None = None


@dataclass(frozen=True)
class ModuleTestsRow:
    """Whether a bucket's module tests fail on its defect (None: they could not run), and why."""

    bucket: str
    tests_dir: str
    fails_on_defect: bool | None
    detail: str


@dataclass(frozen=True)
class NoteRow:
    """What the campaign decided about itself (runs at once, back-offs), with why."""

    time: float
    topic: str
    text: str


@dataclass(frozen=True, kw_only=True)
class CampaignMeta:
    """The campaign's settings and calibration as the journal keeps them (None: not stored yet)."""

    spec: str | None = None
    seed: int | None = None
    strategy: str | None = None
    params: dict[str, list[str]] | None = None
    horizon: float | None = None  # s a case runs at most: given, or derived from the clean runs
    horizon_derived: bool = False  # the horizon came from the stack (the clean runs), not --horizon
    cases: int | None = None
    budget: float | None = None
    calibrated: bool = False
    workers: int | None = None  # the runs at once calibration chose
    timing: Timing | None = None
    overloaded_runs: tuple[str, ...] = ()  # baseline runs of a batch whose timing drifted
    minimise: bool | None = None  # the campaign minimises its confirmed buckets (None: a journal that did not say)

    @classmethod
    def from_json(cls, values: JsonObject) -> CampaignMeta:
        """The settings from the meta table's key → JSON value (keys this version does not know are left out)."""
        known: dict[str, Any] = {k: v for k, v in values.items() if k in cls.__dataclass_fields__}
        timing = known.pop("timing", None)
        runs = known.pop("overloaded_runs", None)
        return cls(**known, timing=Timing(**timing) if timing else None, overloaded_runs=tuple(runs or ()))


@dataclass(frozen=True, kw_only=True)
class BlameRow:
    """A confirmed bucket's module to blame (``blame.Blame``) and its root-cause identity (None: none)."""

    bucket: str
    module: str | None
    output: str | None
    how: str
    chain: str
    detail: str
    twins: int
    identity: str | None
    replay: str | None = None  # how a replay of the module to blame confirmed it (None: none did)

    @property
    def root_cause(self) -> str | None:
        """The root cause it names: the module to blame, the mutated value itself, or None (``blame.Blame``)."""
        return root_cause_of(self.module, self.how)
