"""Typed records of a campaign: a planned case, what a run of it gave, a bucket."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

BASELINE = "baseline"  # a clean run, no mutation
MUTATED = "mutated"  # a generated test case
RERUN = "rerun"  # a bucket's first failure again, for its rate


@dataclass(frozen=True)
class PlannedCase:
    """One run to make: everything a worker needs, nothing it must look up."""

    case_id: str  # "b-0001", "c-000042", "r-<bucket>-1"
    kind: str  # BASELINE, MUTATED or RERUN
    number: int  # order in the campaign
    seed: int  # the strategy's seed for this case (the test case's own is inside the XML)
    params: dict[str, str]
    testcase_xml: str | None  # None: a clean run
    strategy: str = "random"
    parent: str | None = None  # guided: the corpus case this one mutates

    def to_json(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_json(cls, body: dict[str, Any]) -> PlannedCase:
        return cls(**body)


@dataclass(frozen=True)
class Finding:
    """One failure seen in a run: an invariant that broke or a module that died."""

    invariant: str
    crash: str  # CRASH class
    module: str | None
    channel: str | None
    detail: str
    severity: str = "high"  # the invariant's (low … critical); a crash no invariant named: high


@dataclass
class CaseOutcome:
    """What one run of a case gave (JSON-able: it crosses process and machine boundaries)."""

    status: str  # "done", or "error" (the run could not start / be judged)
    verdict: str  # CRASH class of the run ("Pass", "Silent", …) or "?" on error
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

    def to_json(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_json(cls, body: dict[str, Any]) -> CaseOutcome:
        body = dict(body)
        body["findings"] = [Finding(**f) for f in body.get("findings", [])]
        known = cls.__dataclass_fields__
        return cls(**{k: v for k, v in body.items() if k in known})  # a journal of an older version

    @property
    def failed(self) -> bool:
        return self.status == "done" and self.verdict != "Pass"
