"""The newest trigger when the previous cycle ended: a module that takes the newest trigger as a cycle ends.

The one logged AFTER_JITTER_NS before the previous output (the recorder's
skew taken off) is the one such a module had then — one logged just before
the output (or within the skew after it) reached it after that cycle had
ended; and for a module that publishes a while after its cycle ended (a big
message, a loaded machine), the one PUBLISH_JITTER_NS before (slow_planner:
a trigger logged 1.2 ms before the output; its one wrong frame, carried by
the warm state).
"""

from __future__ import annotations

from collections.abc import Iterator

from astaa_deft.analysis.deft.frames.context import OutputContext
from astaa_deft.analysis.deft.frames.rule import FrameRule, Trigger, register

CYCLE_END = "cycle end"


def triggers(ctx: OutputContext) -> Iterator[Trigger]:
    for index in ctx.ends:
        yield index, CYCLE_END


register(FrameRule(name=CYCLE_END, order=30, triggers=triggers, likely=True))
