"""``siblings``: two sibling fields of the same kind exchanged (x sent as y, y as x; lat and lon; width
and length) — both values plausible, each in the wrong place. Neighbours in declaration order pair up."""

from __future__ import annotations

import random

from astaa_deft.model.fields import FieldPath
from astaa_deft.model.sut import FLOAT_KINDS, INT_KINDS
from astaa_deft.engine.intercept.actions.swap import Swap
from astaa_deft.engine.intercept.faults import FAMILIES
from astaa_deft.engine.intercept.faults.base import (
    FaultFamily, Scene, Sources, Span, Target, Targets, consumed_fields, describe, held, once_or_held, one_policy,
)
from astaa_deft.engine.intercept.dictionary import field_site
from astaa_deft.engine.intercept.testcase import Selection, TestCase

SWAPPABLE = frozenset(FLOAT_KINDS + INT_KINDS)


class Siblings(FaultFamily):
    name = "siblings"
    weight = 4
    rank = 12
    semantic = True

    def targets(self, sources: Sources) -> Targets:
        """Each field with its next sibling of the same kind in the same struct (``partner``)."""
        found: Targets = {}
        last: dict[tuple[str, tuple], tuple[FieldPath, str]] = {}  # (channel, parent) -> previous field, kind
        for channel, path, field_type in consumed_fields(sources):
            *parent, leaf = path.segments
            if type(leaf) is not str or field_type.kind not in SWAPPABLE:
                continue
            key = (channel.name, tuple(parent))
            before = last.get(key)
            last[key] = (path, field_type.kind)
            if before is None or _kind_group(before[1]) != _kind_group(field_type.kind):
                continue
            site = field_site(sources.spec.types, channel.type, before[0])
            found.setdefault(channel.name,
                             []).append(Target(channel=channel, path=before[0], site=site, values=(), partner=path))
        return found

    def draw(self, testcase_id: str, rng: random.Random, targets: Targets, scene: Scene) -> TestCase:
        channel = rng.choice(sorted(targets))
        target = rng.choice(targets[channel])
        start = scene.start(rng)
        return self._testcase(testcase_id, rng, target, Span(start, *once_or_held(rng, start, scene.duration),
                                                             scene.anchor))

    def visits(self, target: Target) -> int:
        return 2  # once, held

    def probe(self, testcase_id: str, rng: random.Random, target: Target, *, visit: int, scene: Scene) -> TestCase:
        start = scene.start(rng)
        until = held(rng, start, scene.duration) if visit % 2 else (scene.duration, Selection(limit=1))
        return self._testcase(testcase_id, rng, target, Span(start, *until, scene.anchor))

    def _testcase(self, testcase_id: str, rng: random.Random, target: Target, span: Span) -> TestCase:
        a, b = str(target.path), str(target.partner)
        return one_policy(testcase_id, rng, target.channel.name, Swap(a, b), span=span,
                          description=describe(self.name, target.channel.name, f"{a} swapped with {b}", span))


def _kind_group(kind: str) -> str:
    return "float" if kind in FLOAT_KINDS else "int"


FAMILIES.register(Siblings.name, Siblings())
