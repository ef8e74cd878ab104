"""A module that drops the triggers coming while it is busy, or takes the oldest of a bounded queue.

One that drops them answers the first trigger after its previous output
(logged up to AFTER_JITTER_NS before that output: the module was idle
before the recorder logged it): ``after``. One taking the oldest of a queue
m - 1 deep answers the first one after the output m before (that cycle
freed a place): ``after m``, for m up to 1 + QUEUE_DEPTHS. A trigger logged
within the jitter before the output may as well have reached the module
while it was still busy (and been dropped): then the first one logged after
the output is the answer.
"""

from __future__ import annotations

from bisect import bisect_right
from collections.abc import Iterator

from astaa_deft.analysis.deft.frames.context import AFTER_JITTER_NS, OutputContext
from astaa_deft.analysis.deft.frames.rule import FrameRule, Trigger, register

AFTER = "after"
QUEUE_DEPTHS = 3


def after(m: int) -> str:
    """The way of the first trigger after the output ``m`` before."""
    return AFTER if m == 1 else f"{AFTER} {m}"


def triggers(ctx: OutputContext) -> Iterator[Trigger]:
    if ctx.previous_output_ns is None:
        return
    times = ctx.trigger_times
    outputs = [ctx.previous_output_ns - ctx.skew_ns, *ctx.earlier_outputs_ns][:QUEUE_DEPTHS + 1]
    for m, t_out in enumerate(outputs, start=1):
        first = bisect_right(times, t_out - AFTER_JITTER_NS)
        for index in dict.fromkeys((first, bisect_right(times, t_out))):
            if ctx.within(index):
                yield index, after(m)


register(FrameRule(name=AFTER, order=50, triggers=triggers, ways=tuple(after(m) for m in range(1, QUEUE_DEPTHS + 2)),
                   likely=True))
