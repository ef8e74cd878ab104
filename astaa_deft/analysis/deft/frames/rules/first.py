"""A first output may answer the first trigger the module could plan from, however many came meanwhile.

A first cycle is often the slowest (a module building its state). The
first trigger every input had been heard by, when the log reaches back to
it; with nothing learned yet, a first output tries this frame first.
"""

from __future__ import annotations

from collections.abc import Iterator

from astaa_deft.analysis.deft.frames.context import OutputContext
from astaa_deft.analysis.deft.frames.rule import FrameRule, Trigger, register

FIRST = "first"


def triggers(ctx: OutputContext) -> Iterator[Trigger]:
    if ctx.first_output_reaches_back and ctx.first_plannable is not None:
        yield ctx.first_plannable, FIRST


register(FrameRule(name=FIRST, order=90, triggers=triggers, likely=True, first_output=0))
