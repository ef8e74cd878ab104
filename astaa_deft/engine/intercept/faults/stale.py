"""``stale``: a field carrying an earlier message's value (a producer sending a cached copy): on one
message the previous message's value, held the value from before the window, frozen (``<hold>``)."""

from __future__ import annotations

import random

from astaa_deft.engine.intercept.actions.hold import Hold
from astaa_deft.engine.intercept.faults import FAMILIES
from astaa_deft.engine.intercept.faults.base import (
    FaultFamily, Scene, Sources, Span, Target, Targets, every_consumed_field, describe, held, once_or_held, one_policy,
)
from astaa_deft.engine.intercept.testcase import Selection, TestCase


class Stale(FaultFamily):
    name = "stale"
    weight = 4
    rank = 10
    semantic = True
    # The dictionary's stale copies (``dict:float.previous`` …) are for hand-written cases; this family holds
    # values with <hold> instead, and keeps the exceptional families from drawing them.
    owns = ("float.previous", "int.previous", "string.previous", "enum.previous", "array.previous")

    def targets(self, sources: Sources) -> Targets:
        return every_consumed_field(sources)

    def draw(self, testcase_id: str, rng: random.Random, targets: Targets, scene: Scene) -> TestCase:
        channel = rng.choice(sorted(targets))
        target = rng.choice(targets[channel])
        start = scene.start(rng)
        return self._testcase(testcase_id, rng, target, Span(start, *once_or_held(rng, start, scene.duration),
                                                             scene.anchor))

    def visits(self, target: Target) -> int:
        return 2  # one behind, frozen

    def probe(self, testcase_id: str, rng: random.Random, target: Target, *, visit: int, scene: Scene) -> TestCase:
        start = scene.start(rng)
        until = held(rng, start, scene.duration) if visit % 2 == 0 else (scene.duration, Selection(limit=1))
        return self._testcase(testcase_id, rng, target, Span(start, *until, scene.anchor))

    def _testcase(self, testcase_id: str, rng: random.Random, target: Target, span: Span) -> TestCase:
        path = str(target.path)
        return one_policy(testcase_id, rng, target.channel.name, Hold((path,)), span=span,
                          description=describe(self.name, target.channel.name, f"{path} stale", span))


FAMILIES.register(Stale.name, Stale())
