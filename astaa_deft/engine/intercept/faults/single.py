"""``single``: one exceptional value in one field of one message (42 % of ASTAA's bugs)."""

from __future__ import annotations

import random

from astaa_deft.engine.intercept.faults import FAMILIES
from astaa_deft.engine.intercept.faults.base import (
    FaultFamily, Scene, Sources, Span, Targets, drawn_values, set_testcase,
)
from astaa_deft.engine.intercept.testcase import Selection, TestCase


class Single(FaultFamily):
    name = "single"
    weight = 42
    rank = 0

    def targets(self, sources: Sources) -> Targets:
        return sources.exceptional

    def draw(self, testcase_id: str, rng: random.Random, targets: Targets, scene: Scene) -> TestCase:
        channel = rng.choice(sorted(targets))  # channels equally likely, whatever their field count
        assignments = drawn_values(rng, [rng.choice(targets[channel])])
        start = scene.start(rng)
        return set_testcase(testcase_id, rng, channel, assignments,
                            span=Span(start, scene.duration, Selection(limit=1), scene.anchor), shape=self.name)


FAMILIES.register(Single.name, Single())
