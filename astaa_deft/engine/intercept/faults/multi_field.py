"""``multi_field``: exceptional values in 2–4 fields of one message (22 % of ASTAA's bugs)."""

from __future__ import annotations

import random

from astaa_deft.engine.intercept.faults import FAMILIES
from astaa_deft.engine.intercept.faults.base import (
    FaultFamily, Scene, Sources, Span, Targets, disjoint_sample, drawn_values, set_testcase,
)
from astaa_deft.engine.intercept.testcase import Selection, TestCase

MAX_FIELDS_PER_MESSAGE = 4


class MultiField(FaultFamily):
    name = "multi_field"
    weight = 22
    rank = 1

    def targets(self, sources: Sources) -> Targets:
        return sources.exceptional

    def draw(self, testcase_id: str, rng: random.Random, targets: Targets, scene: Scene) -> TestCase:
        channel = rng.choice(sorted(targets))
        pool = targets[channel]
        assignments = drawn_values(rng, disjoint_sample(rng, pool, rng.randint(2, MAX_FIELDS_PER_MESSAGE)))
        start = scene.start(rng)
        return set_testcase(testcase_id, rng, channel, assignments,
                            span=Span(start, scene.duration, Selection(limit=1), scene.anchor), shape=self.name)


FAMILIES.register(MultiField.name, MultiField())
