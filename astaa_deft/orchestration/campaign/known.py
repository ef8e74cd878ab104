"""Known baseline findings: invariants the unmutated SUT already breaks, and when a case makes one worse (pure).

An invariant that breaks in clean runs is a finding of the SUT, reported
once (its baseline bucket, with its rate). It says nothing about a test
case unless the case makes it *worse*: it breaks clearly earlier than in
any clean run, in more episodes than any clean run had, or with more
violating messages than any clean run had (counts, not rates: a mutated case
runs shorter than a clean one, so a count above every clean run's is worse
whatever the length). Such invariants do not end a case at their first
violation (the runner lets the run go on; they are judged here, after it).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

from astaa_deft.model.json import JsonObject
from astaa_deft.orchestration.journal.model import CaseOutcome

EARLIER_SECONDS = 1.0  # a violation this much earlier than every clean run's (and …)
EARLIER_SHARE = 0.25  # … this share of the clean runs' earliest time) is earlier, not jitter
MORE_VIOLATING = 1.5  # violating messages beyond this many times the clean runs' most (and …)
MORE_VIOLATING_SLACK = 5  # … this many more) is more often


@dataclass(frozen=True, kw_only=True)
class KnownFinding:
    """An invariant the clean runs break: how early, how often, in how many of them."""

    invariant: str
    failing_runs: int
    runs: int
    first_at: float | None  # earliest seconds from a clean run's start to its first violation
    episodes: int  # most episodes (reported violations) in one clean run
    violating: int  # most violating messages in one clean run

    @property
    def rate(self) -> str:
        return f"{self.failing_runs}/{self.runs}"

    def to_json(self) -> JsonObject:
        """Its JSON form."""
        return asdict(self)


def known_findings(clean: list[CaseOutcome]) -> dict[str, KnownFinding]:
    """Per invariant broken in any of these clean runs (finished ones), how it broke there."""
    done = [o for o in clean if o.status == "done"]
    out: dict[str, KnownFinding] = {}
    for name in sorted({f.invariant for o in done for f in o.findings}):
        failing = [o for o in done if any(f.invariant == name for f in o.findings)]
        times = [f.at for o in failing for f in o.findings if f.invariant == name and f.at is not None]
        out[name] = KnownFinding(invariant=name, failing_runs=len(failing), runs=len(done),
                                 first_at=min(times) if times else None,
                                 episodes=max(sum(1 for f in o.findings if f.invariant == name) for o in failing),
                                 violating=max(o.violating.get(name, 0) for o in failing))
    return out


def from_json(body: JsonObject) -> dict[str, KnownFinding]:
    """Invariant → known finding, from invariant → :meth:`KnownFinding.to_json` (TypeError for another shape)."""
    out: dict[str, KnownFinding] = {}
    for name, value in body.items():
        fields: dict[str, Any] = value if isinstance(value, dict) else {}
        out[name] = KnownFinding(**fields)
    return out


def worse(outcome: CaseOutcome, known: KnownFinding) -> str | None:
    """How ``outcome`` breaks the known invariant worse than every clean run did (None: not worse)."""
    mine = [f for f in outcome.findings if f.invariant == known.invariant]
    if not mine:
        return None
    times = [f.at for f in mine if f.at is not None]
    if times and known.first_at is not None:
        margin = max(EARLIER_SECONDS, EARLIER_SHARE * known.first_at)
        if min(times) < known.first_at - margin:
            return f"at {min(times):.1f} s, clean runs not before {known.first_at:.1f} s"
    if len(mine) > known.episodes:
        return f"{len(mine)} episodes, clean runs at most {known.episodes}"
    violating = outcome.violating.get(known.invariant, 0)
    if violating > max(known.violating * MORE_VIOLATING, known.violating + MORE_VIOLATING_SLACK):
        return f"{violating} violating messages, clean runs at most {known.violating}"
    return None


def judged(outcome: CaseOutcome, known: dict[str, KnownFinding]) -> CaseOutcome:
    """The outcome without the findings of known baseline invariants it does not make worse (noted)."""
    if outcome.status != "done" or not outcome.findings or not known:
        return outcome
    same = sorted({f.invariant for f in outcome.findings if f.invariant in known
                   and worse(outcome, known[f.invariant]) is None})
    if not same:
        return outcome
    kept = [f for f in outcome.findings if f.invariant not in same]
    rates = ", ".join(f"{name} ({known[name].rate} clean runs)" for name in same)
    return outcome.keeping(kept, f" (not counted: known baseline finding(s) no worse than without mutation: {rates})")
