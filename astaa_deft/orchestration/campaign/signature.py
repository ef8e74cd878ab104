"""A failure's signature: what groups failures into one bucket.

CRASH class, the invariant (or monitor) that broke, the module held
responsible, and the family of the mutation (channel, field, action) — two
NaNs in the same routing field that both break the speed limit are one bug;
the same invariant broken through another channel is another. A run is
filed under its most severe finding; findings the test case inflicted on
itself do not count (:func:`without_self_inflicted`).
"""

from __future__ import annotations

import re
from collections.abc import Callable, Collection
from dataclasses import replace
from pathlib import Path

from astaa_deft.engine.intercept.testcase import TestCase
from astaa_deft.engine.monitor import MonitorSet
from astaa_deft.engine.monitor.verdict import ORDER
from astaa_deft.model.records import Verdict
from astaa_deft.engine.monitor.violation import SEVERITIES
from astaa_deft.model.sut import Spec
from astaa_deft.orchestration.journal.model import (
    NO_MODULE, NO_MUTATION, UNKNOWN, BucketSignature, CaseOutcome, FailureKey, Finding,
)
from astaa_deft.orchestration.campaign.originals import broken_on_originals

_INDEX = re.compile(r"\[\d+\]")


def primary(outcome: CaseOutcome) -> Finding | None:
    """The finding a run is filed under: its most severe, then the worst CRASH class, then the earliest.

    A collision's clearance warning (medium) comes before the contact
    (critical): the run is the contact's. The monitors report in time order.
    """
    if not outcome.findings:
        return None
    return min(enumerate(outcome.findings), key=lambda item: (*finding_rank(item[1]), item[0]))[1]


def finding_rank(finding: Finding) -> tuple[int, int]:
    """Sort key of a finding, most severe first: (severity, CRASH class); unknown names last."""
    severity = SEVERITIES.index(finding.severity) if finding.severity in SEVERITIES else -1
    crash = ORDER.index(finding.crash) if finding.crash in ORDER else len(ORDER)
    return -severity, crash


def mutation_family(testcase: TestCase | None) -> str:
    """channel:field:action of the test case's mutations (array indices folded), sorted."""
    if testcase is None or not testcase.policies:
        return NO_MUTATION
    parts = set()
    for policy in testcase.policies:
        action = policy.action.name
        fields = list(policy.action.field_paths()) or ["*"]
        for channel in policy.channels or (policy.message_type or "*",):
            for path in fields:
                parts.add(f"{channel}:{_INDEX.sub('[]', str(path))}:{action}")
    return "+".join(sorted(parts))


def fold_indices(path: str) -> str:
    """``points[3].v`` → ``points[].v``: one family for every element of an array."""
    return _INDEX.sub("[]", path)


def failure_key(outcome: CaseOutcome) -> FailureKey:
    """The failure alone (no mutation), from the run's primary finding: compared with the baseline's failures."""
    finding = primary(outcome)
    if finding is None:
        return FailureKey(outcome.verdict, UNKNOWN, UNKNOWN)
    return FailureKey(finding.crash, finding.invariant, finding.module or NO_MODULE, finding.signature)


SAME_PHASE_SECONDS = 2.0  # two errors this close in their runs (and …)
SAME_PHASE_SHARE = 0.25  # … within this share of the later one's time) came at the same phase of the run


def same_failure(finding: Finding, wanted: Finding) -> bool:
    """``finding`` is the failure ``wanted`` is: the same invariant in the same module and, where both name an
    error (an ``exceptions`` traceback, a crash's last words), the same error — its type and innermost frame —
    at the same phase of the run. A twin's ``ValueError`` at the end of its route is not the ``KeyError`` a
    mutated case raised in ``step`` early on, nor is the same error at a far other moment."""
    if finding.invariant != wanted.invariant or finding.module != wanted.module:
        return False
    if not (finding.signature and wanted.signature):
        return True
    if finding.signature != wanted.signature:
        return False
    if finding.at is None or wanted.at is None:
        return True
    later = max(finding.at, wanted.at)
    return abs(finding.at - wanted.at) <= max(SAME_PHASE_SECONDS, SAME_PHASE_SHARE * later)


def failure_signature(outcome: CaseOutcome) -> str:
    """The failure as one comparable string, for a bucket's root-cause identity (with the module to blame and
    the culprit's field family): the primary finding's CRASH class, invariant and module. The one place a
    finer signature of the failure (an exception's type and innermost frame) plugs in."""
    return failure_key(outcome).text()


def field_family(family: str) -> str:
    """A mutation family (``channel:field:action`` parts joined by ``+``) folded to the culprit's field family:
    each field to the object holding it, the action and value left out — ``ego:x:set`` and ``ego:v:set`` are
    ``ego:.{…}``, ``obstacles:obstacles[].length:set`` is ``obstacles:obstacles[].{…}``; a fault on whole
    messages (``*``) is ``channel:(message)``."""
    parts = set()
    for part in family.split("+"):
        channel, _, rest = part.partition(":")
        path = rest.rsplit(":", 1)[0] if ":" in rest else rest
        if not path or path == "*":
            parts.add(f"{channel}:(message)")
            continue
        holder = path.rsplit(".", 1)[0] if "." in path else ""
        parts.add(f"{channel}:{holder}.{{…}}")
    return "+".join(sorted(parts))


def signature(outcome: CaseOutcome, testcase: TestCase | None) -> BucketSignature:
    """The bucket a failing run of ``testcase`` (None: a clean run) belongs in."""
    return BucketSignature(failure_key(outcome), mutation_family(testcase))


def mutated_channels(testcase: TestCase | None, spec: Spec) -> set[str]:
    """Names of the channels the test case's policies rewrite (by channel or by message type)."""
    if testcase is None:
        return set()
    return {c.name for policy in testcase.policies for c in policy.target_channels(spec)}


def invariant_channels(spec: Spec) -> dict[str, frozenset[str]]:
    """Each invariant's name → every channel it reads (a collision invariant: its ego's and its obstacles')."""
    return {m.invariant.name: frozenset(m.channels()) for m in MonitorSet(spec, 0).monitors}


Judge = Callable[[Path, Spec, Collection[str], Collection[str]], "set[str] | None"]


def without_self_inflicted(outcome: CaseOutcome, testcase: TestCase | None, spec: Spec,
                           judge: Judge = broken_on_originals) -> CaseOutcome:
    """The outcome without the findings the test case inflicted on itself.

    The monitors judge what consumers receive, so a NaN written into
    ``command.acceleration`` breaks ``finite_command`` by itself, and a
    collision invariant reading the ego and the obstacles breaks when the
    case blows up an obstacle's length. A finding whose invariant reads any
    channel the case rewrites is therefore judged again on the producers'
    originals (``judge``, over the case's log: :func:`.originals.broken_on_originals`):
    it counts only if the invariant breaks there too (a collision with a
    real obstacle the misled planner drove into); else it says the mutation
    is out of bounds, not that the SUT failed. Without a log to judge on
    (or a finding of no spec invariant on a rewritten channel) it does not
    count. What the SUT does with the value — a module crashing, an
    invariant on channels the case leaves alone — counts as the monitors
    said. A run left with no finding is not a failure.
    """
    mutated = mutated_channels(testcase, spec)
    if not mutated or outcome.status != "done":
        return outcome
    reads = invariant_channels(spec)
    touched = {name for name, channels in reads.items() if channels & mutated}
    margins = {name: m for name, m in outcome.margins.items() if name not in touched}  # guided: not a closer approach
    suspects = {f.invariant for f in outcome.findings
                if f.invariant in touched or (f.invariant not in reads and f.channel in mutated)}
    if not suspects:
        return replace(outcome, margins=margins)
    judged = suspects & touched
    still: set[str] | None = None
    if judged and outcome.log_path:
        channels = mutated & set().union(*(reads[name] for name in judged))
        still = judge(Path(outcome.log_path), spec, judged, channels)
    real = still or set()
    kept = [f for f in outcome.findings if f.invariant not in suspects or f.invariant in real]
    dropped = sorted(suspects - real)
    notes = []
    if dropped:
        how = "broke on the rewritten messages only" if still is not None else "not judged on the originals"
        notes.append(f"not counted: {', '.join(dropped)} ({how}; the case rewrites {', '.join(sorted(mutated))})")
    if real:
        notes.append(f"counted: {', '.join(sorted(real))} broke on the producers' originals too")
    note = f" ({'; '.join(notes)})"
    if len(kept) == len(outcome.findings):
        return replace(outcome, margins=margins, summary=outcome.summary + note)
    if not kept:
        return replace(outcome, verdict=Verdict.PASS,
                       summary=f"{Verdict.PASS}: only the mutated values themselves broke invariants{note}",
                       findings=[], margins=margins)
    klass = next(c for c in ORDER if any(f.crash == c for f in kept) or c is Verdict.PASS)
    return replace(outcome, verdict=klass if klass is not Verdict.PASS else outcome.verdict, findings=kept,
                   summary=outcome.summary + note, margins=margins)
