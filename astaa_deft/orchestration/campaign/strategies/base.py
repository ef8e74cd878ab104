"""The strategy interface: propose the n-th test case, learn from what runs gave.

:class:`Strategy` declares every hook the campaign calls, each with a
do-nothing default; a strategy overrides the ones it uses. The campaign
calls every hook on every strategy (no probing for optional methods).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Collection, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

from astaa_deft.engine.intercept.dictionary import Dictionary
from astaa_deft.engine.intercept.testcase import TestCase
from astaa_deft.model.sut import Spec
from astaa_deft.orchestration.journal.journal import Journal
from astaa_deft.orchestration.journal.model import CaseOutcome, PlannedCase, Timing
from astaa_deft.model.registry import Registry


@dataclass(frozen=True)
class Proposal:
    """A strategy's next test case and the case it was derived from, if any."""

    testcase: TestCase
    parent: str | None = None  # the case it was derived from, if any


class Strategy(ABC):
    """How a campaign draws its test cases. Not thread-safe: the campaign calls the hooks from its own thread.

    The campaign's order of calls: ``__init__``; ``observe_baseline`` per
    finished clean baseline run; ``calibrate`` once the baseline measured
    the live timing; on resume ``resume`` with the generated cases already
    planned, then ``observe`` for each of them that finished; then
    ``propose``/``judge``/``observe`` per case; at the end ``finish``.
    """

    name: ClassVar[str]
    # True: the strategy turns its buckets into findings itself (``finish``); the campaign then does not
    # minimise them.
    exports_own_findings: ClassVar[bool] = False

    @abstractmethod
    def __init__(self, spec: Spec, dictionary: Dictionary, seed: int, duration: float) -> None:
        """A strategy for ``spec``'s channels, drawing values from ``dictionary``, deterministic given ``seed``;
        ``duration``: the seconds a case's windows may span until :meth:`calibrate` says better. InputError
        when the spec gives the strategy nothing to work on."""

    @abstractmethod
    def propose(self, number: int) -> Proposal:
        """The ``number``-th test case; deterministic given the seed and what was observed before."""

    def observe(self, case_id: str, testcase: TestCase | None, outcome: CaseOutcome) -> None:  # noqa: B027 (optional hook)
        """A finished generated case (in the order results arrive). Default: nothing learnt."""

    def observe_baseline(self, case_id: str, outcome: CaseOutcome) -> None:  # noqa: B027 (optional hook)
        """A finished clean baseline run (every one, before the first :meth:`propose`). Default: ignored."""

    def calibrate(self, timing: Timing) -> None:  # noqa: B027 (optional hook)
        """When the SUT is live, as the baseline measured it (once, before the first :meth:`propose`).
        Default: ignored."""

    def resume(self, planned: Sequence[PlannedCase]) -> None:  # noqa: B027 (optional hook)
        """On resume: the generated cases the campaign had planned already, in order (before their outcomes
        reach :meth:`observe`). Default: ignored."""

    def leave_out(self, fields: Collection[tuple[str, str]]) -> int:
        """Before the first :meth:`propose`: leave these (channel, field path) out of generation (fields no
        module reads, as the module-level search measured); the generation targets left out. Default: none."""
        return 0

    def judge(self, case_id: str, testcase: TestCase | None, outcome: CaseOutcome, learn: bool = True) -> CaseOutcome:
        """The outcome of a generated case or its re-run as this strategy's oracle sees it (``learn``: a
        generated case, not a re-run). Default: the outcome as the monitors judged it."""
        return outcome

    def finish(self, journal: Journal, out: Path, spec_path: Path, say: Callable[[str], None]) -> None:  # noqa: B027 (optional hook)
        """After the hunt (not after an interruption): the strategy's own findings from ``journal`` into
        ``out`` (when :attr:`exports_own_findings`). Default: nothing."""


__all__ = ["Proposal", "Strategy", "Timing"]


# Every strategy by its name (``fuzz --strategy``): each strategy's module registers its class
# (``@STRATEGIES.register_class``); the campaign and the command line's choices read it.
STRATEGIES: Registry[type[Strategy]] = Registry("strategy", "astaa_deft.orchestration.campaign.strategies",
                                                skip=("base", "decictor_export"))
