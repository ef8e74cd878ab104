"""A plain replay's frame, last: the newest trigger with the inputs as logged before it.

Even older inputs than the previous frame used: that frame may have
reproduced its output with an input the module got later.
"""

from __future__ import annotations

from astaa_deft.analysis.deft.frames.context import OutputContext
from astaa_deft.analysis.deft.frames.rule import FrameRule, register
from astaa_deft.analysis.deft.frames.streams import Candidate, frame_at

AS_LOGGED = "as logged"


def frame(ctx: OutputContext) -> Candidate | None:
    t_t = ctx.trigger_times[ctx.newest]
    choice = frame_at(ctx.streams, ctx.trigger, ctx.newest, t_t, {}, absent=True)
    return None if choice is None else Candidate(frame_time=t_t, choice=choice, patterns=frozenset({(AS_LOGGED, ())}))


register(FrameRule(name=AS_LOGGED, order=100, frame=frame))
