"""A failure's signature: what groups failures into one bucket.

CRASH class, the invariant (or monitor) that broke, the module held
responsible, and the family of the mutation (channel, field, action) — two
NaNs in the same routing field that both break the speed limit are one bug;
the same invariant broken through another channel is another.
"""

from __future__ import annotations

import re
from dataclasses import replace

from ..intercept.testcase import TestCase, parse_testcase
from ..monitor.verdict import ORDER
from .model import CaseOutcome, Finding

NO_MUTATION = "(no mutation)"
_INDEX = re.compile(r"\[\d+\]")


def primary(outcome: CaseOutcome) -> Finding | None:
    """The finding a run is filed under: its earliest (the monitors report in time order)."""
    return outcome.findings[0] if outcome.findings else None


def mutation_family(testcase: TestCase | None) -> str:
    """channel:field:action of the test case's mutations (array indices folded), sorted."""
    if testcase is None or not testcase.policies:
        return NO_MUTATION
    parts = set()
    for policy in testcase.policies:
        action = getattr(policy.action, "name", type(policy.action).__name__.lower())
        fields = [a.path for a in getattr(policy.action, "fields", ())] or ["*"]
        for channel in policy.channels or (policy.message_type or "*",):
            for path in fields:
                parts.add(f"{channel}:{_INDEX.sub('[]', str(path))}:{action}")
    return "+".join(sorted(parts))


def fold_indices(path: str) -> str:
    """``points[3].v`` → ``points[].v``: one family for every element of an array."""
    return _INDEX.sub("[]", path)


def failure_key(outcome: CaseOutcome) -> str:
    """The failure alone (no mutation): compared with the baseline's failures."""
    finding = primary(outcome)
    if finding is None:
        return f"{outcome.verdict}|?|?"
    return f"{finding.crash}|{finding.invariant}|{finding.module or '-'}"


def signature(outcome: CaseOutcome, testcase_xml: str | None) -> str:
    testcase = parse_testcase(testcase_xml.encode()) if testcase_xml else None
    return f"{failure_key(outcome)}|{mutation_family(testcase)}"


def mutated_channels(testcase_xml: str | None, spec) -> set[str]:
    """Names of the channels the test case's policies rewrite (by channel or by message type)."""
    if not testcase_xml:
        return set()
    testcase = parse_testcase(testcase_xml.encode())
    return {c.name for policy in testcase.policies for c in policy.target_channels(spec)}


def without_self_inflicted(outcome: CaseOutcome, testcase_xml: str | None, spec) -> CaseOutcome:
    """The outcome without findings on a channel the test case itself rewrites.

    The monitors judge what consumers receive, so a NaN written into
    ``command.acceleration`` breaks ``finite_command`` by itself: that says the
    mutation is out of bounds, not that the SUT failed. What the SUT does
    with it (a module crashing, another channel going wrong) still counts.
    A run left with no finding is not a failure.
    """
    mutated = mutated_channels(testcase_xml, spec)
    if not mutated or outcome.status != "done":
        return outcome
    own = {inv.name for inv in spec.invariants if getattr(inv, "channel", None) in mutated}
    margins = {name: m for name, m in outcome.margins.items() if name not in own}  # guided: not a closer approach
    kept = [f for f in outcome.findings if f.channel is None or f.channel not in mutated]
    if len(kept) == len(outcome.findings):
        return replace(outcome, margins=margins)
    dropped = sorted({f.invariant for f in outcome.findings if f not in kept})
    note = f" (not counted: {', '.join(dropped)} on the mutated channel(s) {', '.join(sorted(mutated))})"
    if not kept:
        return replace(outcome, verdict="Pass", summary=f"Pass: only the mutated values themselves broke"
                                                        f" invariants{note}", findings=[], margins=margins)
    klass = next(c for c in ORDER if any(f.crash == c for f in kept) or c == "Pass")
    return replace(outcome, verdict=klass if klass != "Pass" else outcome.verdict, findings=kept,
                   summary=outcome.summary + note, margins=margins)
