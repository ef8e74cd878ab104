"""``sustained``: one exceptional value held on every message of a 1–5 s window or on the next 5–50
messages (a stack that ignores one bad message may not ignore it held)."""

from __future__ import annotations

import random

from astaa_deft.engine.intercept.faults import FAMILIES
from astaa_deft.engine.intercept.faults.base import (
    FaultFamily, Scene, Sources, Span, Targets, drawn_values, held, set_testcase,
)
from astaa_deft.engine.intercept.testcase import TestCase


class Sustained(FaultFamily):
    name = "sustained"
    weight = 20
    rank = 3

    def targets(self, sources: Sources) -> Targets:
        return sources.exceptional

    def draw(self, testcase_id: str, rng: random.Random, targets: Targets, scene: Scene) -> TestCase:
        channel = rng.choice(sorted(targets))
        assignments = drawn_values(rng, [rng.choice(targets[channel])])
        start = scene.start(rng)
        return set_testcase(testcase_id, rng, channel, assignments,
                            span=Span(start, *held(rng, start, scene.duration), scene.anchor), shape=self.name)


FAMILIES.register(Sustained.name, Sustained())
