"""``type``: a field removed, ``null``, or of another JSON type (a number sent as a string, an array as an
object) — what a producer built from another version of the schema sends."""

from __future__ import annotations

import random

from astaa_deft.model.sut import FLOAT_KINDS, INT_KINDS
from astaa_deft.engine.intercept.actions.base import ActionConfig
from astaa_deft.engine.intercept.actions.remove import Remove
from astaa_deft.engine.intercept.actions.set import Assignment, Set
from astaa_deft.engine.intercept.faults import FAMILIES
from astaa_deft.engine.intercept.faults.base import (
    FaultFamily, Scene, Sources, Span, Target, Targets, every_consumed_field, describe, held, once_or_held, one_policy,
)
from astaa_deft.engine.intercept.testcase import Selection, TestCase

REMOVED = "removed"
# Another JSON type per declared kind, in the order a coverage round tries them (after removed and null).
_NUMBER = ('json:"1"', "json:true", "json:[]")
OTHER_TYPES: dict[str, tuple[str, ...]] = {
    **{kind: _NUMBER for kind in FLOAT_KINDS + INT_KINDS + ("time",)},
    "bool": ('json:"true"', "json:[]"), "string": ("json:0", "json:[]"), "enum": ("json:[]", "json:{}"),
    "bytes": ("json:0",), "array": ("json:{}", 'json:"[]"'),
}


def faults_of(target: Target) -> tuple[str, ...]:
    """The faults a field can take: removed (a struct field, not an array element), null, other types."""
    removable = type(target.path.segments[-1]) is str
    return ((REMOVED,) if removable else ()) + ("json:null",) + OTHER_TYPES.get(target.site.field_type.kind, ())


class JsonType(FaultFamily):
    name = "type"
    weight = 5
    rank = 11
    semantic = True

    def targets(self, sources: Sources) -> Targets:
        return every_consumed_field(sources)

    def draw(self, testcase_id: str, rng: random.Random, targets: Targets, scene: Scene) -> TestCase:
        channel = rng.choice(sorted(targets))
        target = rng.choice(targets[channel])
        fault = rng.choice(faults_of(target))
        start = scene.start(rng)
        return self._testcase(testcase_id, rng, target, fault,
                              span=Span(start, *once_or_held(rng, start, scene.duration), scene.anchor))

    def visits(self, target: Target) -> int:
        return len(faults_of(target))

    def probe(self, testcase_id: str, rng: random.Random, target: Target, *, visit: int, scene: Scene) -> TestCase:
        faults = faults_of(target)
        start = scene.start(rng)
        until = held(rng, start, scene.duration) if rng.random() < 1 / 3 else (scene.duration, Selection(limit=1))
        return self._testcase(testcase_id, rng, target, faults[visit % len(faults)],
                              span=Span(start, *until, scene.anchor))

    def _testcase(self, testcase_id: str, rng: random.Random, target: Target, fault: str, *, span: Span) -> TestCase:
        path = str(target.path)
        action: ActionConfig = Remove((path,)) if fault == REMOVED else Set((Assignment(path, fault),))
        what = f"{path} removed" if fault == REMOVED else f"{path} = {fault}"
        return one_policy(testcase_id, rng, target.channel.name, action, span=span,
                          description=describe(self.name, target.channel.name, what, span))


FAMILIES.register(JsonType.name, JsonType())
