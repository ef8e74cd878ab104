"""What the parts of a campaign share: its state, its planned cases, and the seams between its parts.

:class:`~.campaign.Campaign` is assembled from one part per concern, each its
own module: :class:`~.baseline.Baseline` (clean runs: horizon, live timing,
known baseline findings), :class:`~.scheduling.Scheduling` (runs at once,
the pool), :class:`~.judging.Judging` (a finished case into its bucket, a
bucket confirmed, decided and blamed) and
:class:`~.minimisation_slots.MinimisationSlots` (confirmed buckets minimised
in worker slots). Each part derives from :class:`CampaignParts`: the state
the campaign's ``__init__`` sets, declared here, and the methods one part
calls on another, declared abstract here and defined by the part that owns
them — so a part names what it needs of the others, and mypy checks it.
"""

from __future__ import annotations

import threading
from abc import ABC, abstractmethod
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from typing import TYPE_CHECKING

from astaa_deft.engine.intercept.dictionary import Dictionary
from astaa_deft.engine.intercept.testcase import TestCase
from astaa_deft.model.sut import Spec
from astaa_deft.orchestration.journal.journal import Journal
from astaa_deft.orchestration.campaign.known import KnownFinding
from astaa_deft.orchestration.campaign.minimiser import Minimised
from astaa_deft.orchestration.journal.model import BucketKind, BucketSignature, CaseOutcome, PlannedCase, Timing
from astaa_deft.orchestration.campaign.payload import CasePool, read_testcase
from astaa_deft.orchestration.journal.rows import CaseRow
from astaa_deft.orchestration.campaign.strategies import Strategy

if TYPE_CHECKING:  # the campaign is assembled from the parts (campaign.py imports this module)
    from astaa_deft.orchestration.campaign.campaign import CampaignConfig


class CampaignParts(ABC):
    """The campaign's state (set by ``Campaign.__init__``) and the seams between its parts."""

    config: CampaignConfig
    journal: Journal
    say: Callable[[str], None]
    spec: Spec
    dictionary: Dictionary
    clean_horizon: float  # s a clean run may last
    horizon: float  # s a mutated case may last (derived from the clean runs unless --horizon gave it)
    strategy: Strategy
    grid: list[dict[str, str]]  # every combination of the params
    cores: int
    calibrated: bool  # runs at once are measured (neither --workers nor --cluster)
    workers: int  # runs at once
    started: float
    timing: Timing
    known: dict[str, KnownFinding]
    shutdown_delays: dict[str, float]  # an ending module -> the seconds its exit may come after its last message
    _clean: list[CaseOutcome]
    _solo: dict[str, CaseOutcome]
    _last_change: float
    _ceiling: int | None
    _ceiling_other: float
    _minimiser: ThreadPoolExecutor | None
    _minimising: dict[Future, str]  # minimisation in flight → its bucket
    _running_cases: set[str]
    _cancel: threading.Event
    _fixed: set[str]
    _testcases: dict[str, TestCase | None]

    # -- planned cases: journalled with their test case's text, kept at hand as objects -----------------------
    def _plan(self, case: PlannedCase) -> None:
        """Journal a planned case; its test case stays at hand as an object (the journal keeps its text)."""
        self._testcases[case.case_id] = case.testcase
        self.journal.plan(case)

    def _testcase(self, row: CaseRow) -> TestCase | None:
        """A planned case's test case: as planned, or (planned before a resume) read back from the journal,
        checked against the spec and dictionaries."""
        if row.case_id not in self._testcases:
            self._testcases[row.case_id] = read_testcase(row.testcase_xml, f"{self.journal.path}: {row.case_id}",
                                                         self.spec, self.dictionary)
        return self._testcases[row.case_id]

    def _planned(self, row: CaseRow) -> PlannedCase:
        return row.planned(self._testcase(row))

    # -- the seams: what one part calls on another (each defined by the part named) ------------------------------
    @abstractmethod
    def _progress(self) -> None:
        """The campaign: tell its caller where it is (``on_progress``)."""

    @abstractmethod
    def _run_pending_baseline(self, pool: CasePool, at_once: int | None = None, last: int | None = None) -> None:
        """Scheduling: run the planned baseline runs."""

    @abstractmethod
    def _calibrate_workers(self, pool: CasePool, per_value: int) -> None:
        """Scheduling: runs at once, measured in the baseline."""

    @abstractmethod
    def _solo_runs(self) -> dict[str, CaseOutcome]:
        """Scheduling: the runs alone of each param value (the timing reference)."""

    @abstractmethod
    def _busy(self) -> int:
        """Scheduling: worker slots taken."""

    @abstractmethod
    def _watch_timing(self, row: CaseRow, outcome: CaseOutcome) -> None:
        """Scheduling: a control run's timing against the run alone."""

    @abstractmethod
    def _plan_baseline(self, count: int) -> None:
        """Baseline: plan baseline runs up to ``count``."""

    @abstractmethod
    def _learn_clean_failure(self, outcome: CaseOutcome) -> None:
        """Baseline: a clean run that failed after the baseline becomes a known finding."""

    @abstractmethod
    def _module_level_blame(self, bucket: str, case: CaseRow) -> tuple[str, str] | None:
        """ModuleLevel: for the live case of a module-level finding, (the module whose replay failed, how);
        its DeFT module test journalled for ``bucket``. None for any other case."""

    @abstractmethod
    def _bucket(self, signature: BucketSignature, outcome: CaseOutcome, case_id: str, kind: BucketKind) -> str:
        """Judging: the bucket of a signature (a new one opened)."""

    @abstractmethod
    def _finished(self, case_id: str, outcome: CaseOutcome) -> list[PlannedCase]:
        """Judging: a finished case judged and journalled; the cases it plans."""

    @abstractmethod
    def _replay_confirms_blame(self, name: str, result: Minimised) -> None:
        """Judging: a minimisation's replay confirms the bucket's blame."""
