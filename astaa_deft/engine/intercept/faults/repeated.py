"""``repeated``: one exceptional value on many messages of a 1–5 s window (8 % of ASTAA's bugs)."""

from __future__ import annotations

import random

from astaa_deft.engine.intercept.faults import FAMILIES
from astaa_deft.engine.intercept.faults.base import (
    FaultFamily, Scene, Sources, Span, Targets, drawn_values, set_testcase,
)
from astaa_deft.engine.intercept.testcase import Selection, TestCase


class Repeated(FaultFamily):
    name = "repeated"
    weight = 8
    rank = 2

    def targets(self, sources: Sources) -> Targets:
        return sources.exceptional

    def draw(self, testcase_id: str, rng: random.Random, targets: Targets, scene: Scene) -> TestCase:
        channel = rng.choice(sorted(targets))
        assignments = drawn_values(rng, [rng.choice(targets[channel])])
        start = scene.start(rng)
        end = min(round(start + rng.uniform(1.0, 5.0), 1), scene.duration)
        selection = rng.choice([Selection(), Selection(every=rng.choice([2, 5, 10])),
                                Selection(probability=rng.choice([0.1, 0.25, 0.5]))])
        return set_testcase(testcase_id, rng, channel, assignments,
                            span=Span(start, end, selection, scene.anchor), shape=self.name)


FAMILIES.register(Repeated.name, Repeated())
