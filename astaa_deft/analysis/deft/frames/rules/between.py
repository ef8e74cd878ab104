"""Every other trigger the output may answer, oldest first: ``between`` (``earlier`` for a first output).

Last of the trigger rules that place every trigger in reach, it names each
trigger placed so far that no rule named: a trigger between, not a way a
module follows (search_policy tries them after the likely ways').
"""

from __future__ import annotations

from collections.abc import Iterator

from astaa_deft.analysis.deft.frames.context import OutputContext
from astaa_deft.analysis.deft.frames.rule import FrameRule, Trigger, register

BETWEEN, EARLIER = "between", "earlier"


def triggers(ctx: OutputContext) -> Iterator[Trigger]:
    for index in range(ctx.oldest + 1, ctx.newest):
        yield index, None


def rest(ctx: OutputContext) -> str:
    return BETWEEN if ctx.has_previous else EARLIER


register(FrameRule(name=BETWEEN, order=80, triggers=triggers, names_rest=rest, ways=(BETWEEN, EARLIER)))
