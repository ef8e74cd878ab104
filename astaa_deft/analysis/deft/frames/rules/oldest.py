"""The oldest trigger not yet answered: a module that lags behind its triggers answers them in order."""

from __future__ import annotations

from collections.abc import Iterator

from astaa_deft.analysis.deft.frames.context import OutputContext
from astaa_deft.analysis.deft.frames.rule import FrameRule, Trigger, register

OLDEST = "oldest"


def triggers(ctx: OutputContext) -> Iterator[Trigger]:
    if ctx.oldest <= ctx.newest:  # a first output's oldest is placed here, named by the rule of the rest
        yield ctx.oldest, (OLDEST if ctx.has_previous else None)


register(FrameRule(name=OLDEST, order=70, triggers=triggers, likely=True))
