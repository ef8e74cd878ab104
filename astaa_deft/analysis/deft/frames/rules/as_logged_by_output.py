"""A plain replay's frame without the skew, last: the newest trigger logged by the output itself.

The other rules look up to the recorder's skew past the output, since an
input logged a moment after the output may have reached the module before
it. But a module that answers on a timer may plan twice on one trigger
message; when a newer trigger came within the skew after the second plan,
every trigger rule starts after the previous frame's and ``as logged``
takes that newer one — and the frame the module really used, the one a
plain replay steps, is proposed by no rule. Tried only when it is another
trigger than ``as logged``'s.
"""

from __future__ import annotations

from astaa_deft.analysis.deft.frames.context import OutputContext
from astaa_deft.analysis.deft.frames.rule import FrameRule, register
from astaa_deft.analysis.deft.frames.streams import Candidate, frame_at, newest_at_or_before

AS_LOGGED_BY_OUTPUT = "as logged by the output"


def frame(ctx: OutputContext) -> Candidate | None:
    index = newest_at_or_before(ctx.trigger_times, ctx.output_ns - ctx.skew_ns)
    if index < 0 or index == ctx.newest:
        return None
    t_t = ctx.trigger_times[index]
    choice = frame_at(ctx.streams, ctx.trigger, index, t_t, {}, absent=True)
    if choice is None:
        return None
    return Candidate(frame_time=t_t, choice=choice, patterns=frozenset({(AS_LOGGED_BY_OUTPUT, ())}))


register(FrameRule(name=AS_LOGGED_BY_OUTPUT, order=101, frame=frame))
