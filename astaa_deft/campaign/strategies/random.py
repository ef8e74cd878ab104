"""ASTAA's weighted random generation (:mod:`astaa_deft.intercept.generate`), one case at a time.

Case ``n`` is exactly ``astaa-deft generate --seed S`` test case ``n``:
the same seed gives the same cases locally and on a cluster, in any order.
"""

from __future__ import annotations

import random

from ...intercept import generate as gen
from ...intercept.dictionary import Dictionary
from ...spec.model import Spec
from ..model import CaseOutcome
from .base import Proposal

ID_WIDTH = 6


class RandomStrategy:
    name = "random"

    def __init__(self, spec: Spec, dictionary: Dictionary, seed: int, duration: float):
        # generate() with count=0 checks the spec offers a field to mutate (InputError otherwise).
        self.by_channel = gen._targets_by_channel(spec, dictionary, False)
        gen.generate(spec, dictionary, 0, seed, duration)
        self.seed = seed
        self.duration = duration

    def propose(self, number: int) -> Proposal:
        testcase = gen._testcase(f"tc-{number:0{ID_WIDTH}d}", random.Random(f"{self.seed}/{number}"),
                                 self.by_channel, self.duration)
        return Proposal(testcase.to_xml().decode())

    def observe(self, case_id: str, testcase_xml: str | None, outcome: CaseOutcome) -> None:
        pass  # random does not learn
