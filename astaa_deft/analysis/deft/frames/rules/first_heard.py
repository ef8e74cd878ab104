"""A first output may answer the very first trigger in the log, some input not heard from yet.

A module that cycles with an input absent (see ``frame_at``): the first
trigger, when it is not the first every input had been heard by; tried
right after that one by a first output with nothing learned yet.
"""

from __future__ import annotations

from collections.abc import Iterator

from astaa_deft.analysis.deft.frames.context import OutputContext
from astaa_deft.analysis.deft.frames.rule import FrameRule, Trigger, register

FIRST_HEARD = "first heard"


def triggers(ctx: OutputContext) -> Iterator[Trigger]:
    if ctx.first_output_reaches_back and ctx.first_plannable != 0:
        yield 0, FIRST_HEARD


register(FrameRule(name=FIRST_HEARD, order=95, triggers=triggers, likely=True, first_output=1))
