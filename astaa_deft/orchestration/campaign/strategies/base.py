"""The strategy interface: propose the n-th test case, learn from what runs gave."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

from astaa_deft.engine.intercept.dictionary import Dictionary
from astaa_deft.model.sut import Spec
from astaa_deft.orchestration.campaign.model import CaseOutcome


@dataclass(frozen=True)
class Timing:
    """When a generated case's windows open: counted from the first message on ``anchor`` (None: from
    the run's start), inside the first ``live`` seconds. The campaign measures both in its baseline runs:
    the anchor is the channel whose first message came last (the whole stack is running then), ``live``
    how long the baseline ran on from there."""

    anchor: str | None
    live: float


@dataclass(frozen=True)
class Proposal:
    testcase_xml: str
    parent: str | None = None  # the case it was derived from, if any


class Strategy(Protocol):
    name: str

    def __init__(self, spec: Spec, dictionary: Dictionary, seed: int, duration: float) -> None: ...

    def propose(self, number: int) -> Proposal:
        """The ``number``-th test case; deterministic given the seed and what was observed before."""

    def observe(self, case_id: str, testcase_xml: str | None, outcome: CaseOutcome) -> None:
        """A finished case (in the order results arrive)."""
