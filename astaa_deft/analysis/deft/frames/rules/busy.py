"""A busy module: its next cycle starts as it ends one, on the newest trigger when its previous output went out.

Two placements of one way: the trigger newest at the previous output (named
busy where it is also the cycle end's: one logged after the cycle end is
the ``after`` trigger), and, after the queue rules' triggers, those logged
up to ``lookback`` before the previous output (a busy module's cycle ended
a little before its output was logged: the output's own delivery), unless
the cycle end names them (a busy trigger's would win its outputs too).
"""

from __future__ import annotations

from bisect import bisect_right
from collections.abc import Iterator

from astaa_deft.analysis.deft.frames.context import OutputContext
from astaa_deft.analysis.deft.frames.rule import FrameRule, Trigger, register

BUSY = "busy"


def triggers(ctx: OutputContext) -> Iterator[Trigger]:
    busy = ctx.busy
    if ctx.within(busy) and busy == ctx.cycle_end:
        yield busy, BUSY
    elif ctx.oldest <= busy < ctx.newest:
        yield busy, None


def jitter(ctx: OutputContext) -> Iterator[Trigger]:
    if ctx.previous_output_ns is None:
        return
    reach = max(ctx.oldest, bisect_right(ctx.trigger_times, ctx.previous_output_ns - ctx.lookback_ns))
    for index in range(ctx.busy - 1, reach - 1, -1):
        yield index, (None if index in ctx.ends else BUSY)


register(FrameRule(name=BUSY, order=40, triggers=triggers, likely=True))
register(FrameRule(name="busy jitter", order=60, triggers=jitter, ways=(BUSY,), likely=True))
