"""How a ``--budget`` is split between the module-level search and the live hunt, from what each level measured.

Pure: the same measurements give the same split. Each level's worth is its
expected finds per core-second: ``(findings + 1) / (cases + 2)`` finds a case
(Laplace's rule: a level that has run nothing yet, or found nothing yet, is
neither written off nor taken for a sure thing) over its measured cost a
case in core-seconds. The module level's share of the budget is its part of
the two worths, held between :data:`MIN_SHARE` and :data:`MAX_SHARE`: live
cases are the truth (every module-level finding is confirmed by one, and
they find what no open-loop replay can), so the live hunt always keeps at
least half, and the search at least its first round.
"""

from __future__ import annotations

from dataclasses import dataclass

from astaa_deft.model.json import JsonObject

MIN_SHARE = 0.05
MAX_SHARE = 0.5


@dataclass(frozen=True, kw_only=True)
class LevelMeasure:
    """What one level measured so far: cases run, what a case cost (core-seconds), findings (buckets)."""

    cases: int
    cost: float  # core-seconds a case
    findings: int

    @property
    def worth(self) -> float:
        """Expected finds per core-second."""
        return (self.findings + 1) / (self.cases + 2) / max(self.cost, 1e-6)

    def to_json(self) -> JsonObject:
        return {"cases": self.cases, "cost": round(self.cost, 6), "findings": self.findings}


@dataclass(frozen=True, kw_only=True)
class Split:
    """The module level's share of the budget, its seconds, and why."""

    share: float
    seconds: float
    module: LevelMeasure
    live: LevelMeasure

    @property
    def why(self) -> str:
        m, live = self.module, self.live
        clamp = (" (at most half: live cases are the truth)" if self.share >= MAX_SHARE
                 else f" (at least {MIN_SHARE:.0%})" if self.share <= MIN_SHARE else "")
        return (f"module level {self.share:.0%} of the budget{clamp}: {m.worth:.3g} expected finds per core-second"
                f" ({m.findings} in {m.cases} case(s), {m.cost:.3g} core-s a case) against live {live.worth:.3g}"
                f" ({live.findings} in {live.cases} case(s), {live.cost:.3g} core-s a case)")

    def to_json(self) -> JsonObject:
        return {"share": round(self.share, 4), "seconds": round(self.seconds, 3), "module": self.module.to_json(),
                "live": self.live.to_json()}


def decide_split(*, module: LevelMeasure, live: LevelMeasure, budget: float) -> Split:
    """The module level's share of ``budget`` seconds from the two levels' measurements."""
    share = module.worth / (module.worth + live.worth)
    share = min(MAX_SHARE, max(MIN_SHARE, share))
    return Split(share=share, seconds=share * budget, module=module, live=live)


__all__ = ["MAX_SHARE", "MIN_SHARE", "LevelMeasure", "Split", "decide_split"]
