"""A failure's signature: what groups failures into one bucket.

CRASH class, the invariant (or monitor) that broke, the module held
responsible, and the family of the mutation (channel, field, action) — two
NaNs in the same routing field that both break the speed limit are one bug;
the same invariant broken through another channel is another.
"""

from __future__ import annotations

import re

from ..intercept.testcase import TestCase, parse_testcase
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


def failure_key(outcome: CaseOutcome) -> str:
    """The failure alone (no mutation): compared with the baseline's failures."""
    finding = primary(outcome)
    if finding is None:
        return f"{outcome.verdict}|?|?"
    return f"{finding.crash}|{finding.invariant}|{finding.module or '-'}"


def signature(outcome: CaseOutcome, testcase_xml: str | None) -> str:
    testcase = parse_testcase(testcase_xml.encode()) if testcase_xml else None
    return f"{failure_key(outcome)}|{mutation_family(testcase)}"
