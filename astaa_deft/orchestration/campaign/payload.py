"""What the campaign hands a pool for one case, and what it needs of a pool.

:class:`CasePayload` is the case's JSON form on the way to a worker (the
keys ``worker.execute`` reads); :class:`CasePool` is the interface the
campaign drives (``executors.LocalPool`` and ``executors.DaskPool`` have it).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import Protocol

from astaa_deft.model.json import JsonObject
from astaa_deft.orchestration.campaign.model import CaseOutcome, PlannedCase


@dataclass(frozen=True)
class CasePayload:
    """Everything a worker needs to run ``case``, nothing it must look up (paths absolute)."""

    spec: str  # the spec file
    case: PlannedCase
    run_dir: str  # the case's own folder (its log, its modules' output)
    horizon: float  # seconds the run may last at most
    dictionaries: tuple[str, ...]  # dictionary files beside the bundled one
    settle: float | None  # a mutated run ends this long after its last mutation could act (None: never)
    known: tuple[str, ...]  # known baseline findings: a mutated run does not end at these

    def to_json(self) -> JsonObject:
        """The payload's JSON form (what the pools pass on to the workers)."""
        return {"spec": self.spec, "case": self.case.to_json(), "run_dir": self.run_dir, "horizon": self.horizon,
                "dictionaries": [path for path in self.dictionaries], "settle": self.settle,
                "known": [name for name in self.known]}


class CasePool(Protocol):
    """Where cases run: submitted cases run concurrently and their outcomes come back as they finish."""

    def submit(self, case_id: str, payload: JsonObject) -> None:
        """Start the case (``payload``: :meth:`CasePayload.to_json`)."""

    def pending(self) -> int:
        """Cases submitted whose outcome has not been taken yet."""

    def done(self, timeout: float | None = None) -> Iterator[tuple[str, CaseOutcome]]:
        """(case id, outcome) of the cases that finished, waiting up to ``timeout`` seconds for the first."""

    def close(self) -> None:
        """Stop the pool's workers (cases still running are abandoned)."""
