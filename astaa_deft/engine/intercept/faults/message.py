"""``message``: reorder, delay, duplicate or drop messages of one channel, no field changed (timing and
ordering bugs need no bad value: a stamp going backwards after a reorder, a late message overtaken by
newer ones). Drawn in campaigns only, next to ASTAA's shapes (its remaining bug classes were timing)."""

from __future__ import annotations

import random

from astaa_deft.engine.intercept.actions.base import ActionConfig
from astaa_deft.engine.intercept.actions.delay import Delay
from astaa_deft.engine.intercept.actions.drop import Drop
from astaa_deft.engine.intercept.actions.duplicate import Duplicate
from astaa_deft.engine.intercept.actions.reorder import Reorder
from astaa_deft.engine.intercept.faults import FAMILIES
from astaa_deft.engine.intercept.faults.base import (
    FaultFamily, Scene, Sources, Span, Targets, one_policy, ordinal,
)
from astaa_deft.engine.intercept.testcase import Selection, TestCase

MESSAGE_FAULTS = ("reorder", "delay", "duplicate", "drop")
DELAYS_MS = (50, 100, 200, 500)


def fault_testcase(testcase_id: str, rng: random.Random, channel: str, fault: str, *, scene: Scene,
                   repeated: bool | None = None) -> TestCase:
    """One message fault on ``channel``: one message, or (``repeated``, else by chance) a burst."""
    action: ActionConfig = {"reorder": Reorder(), "delay": Delay(float(rng.choice(DELAYS_MS))), "drop": Drop(),
                            "duplicate": Duplicate()}[fault]
    start = scene.start(rng)
    if repeated is None:
        repeated = rng.random() < 0.5
    if repeated:
        end = min(round(start + rng.uniform(0.5, 3.0), 1), scene.duration)
        selection = Selection(every=rng.choice([1, 2, 5]))
        which = "every message" if selection.every == 1 else f"every {ordinal(selection.every)} message"
        what = f"{which} from {start} s to {end} s"
    else:
        end, selection = scene.duration, Selection(limit=1)
        what = f"first message after {start} s"
    anchor = scene.anchor
    return one_policy(testcase_id, rng, channel, action, span=Span(start, end, selection, anchor),
                      description=f"{fault}: {channel}: {what}"
                      + (f" (counted from the first {anchor} message)" if anchor else ""))


class Message(FaultFamily):
    name = "message"
    weight = 14
    rank = 5
    campaign_only = True

    def targets(self, sources: Sources) -> Targets:
        return sources.exceptional

    def draw(self, testcase_id: str, rng: random.Random, targets: Targets, scene: Scene) -> TestCase:
        channel = rng.choice(sorted(targets))
        return fault_testcase(testcase_id, rng, channel, rng.choice(MESSAGE_FAULTS), scene=scene)


FAMILIES.register(Message.name, Message())
