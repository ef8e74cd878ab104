"""The newest trigger at the output: a module that keeps up answers the trigger just before its output."""

from __future__ import annotations

from collections.abc import Iterator

from astaa_deft.analysis.deft.frames.context import OutputContext
from astaa_deft.analysis.deft.frames.rule import FrameRule, Trigger, register
from astaa_deft.analysis.deft.frames.streams import newest_at_or_before

NEWEST = "newest"


def triggers(ctx: OutputContext) -> Iterator[Trigger]:
    yield ctx.newest, NEWEST
    # The newest trigger logged before the output itself (not the skew after it): one logged within the skew
    # after the output most likely came after the cycle had started (a plain replay of the output's newest
    # trigger takes this one; drop_cycle_none lost such an output to it).
    unskewed = newest_at_or_before(ctx.trigger_times, ctx.output_ns - ctx.skew_ns)
    if ctx.oldest <= unskewed < ctx.newest:
        yield unskewed, NEWEST


register(FrameRule(name=NEWEST, order=10, triggers=triggers, likely=True))
