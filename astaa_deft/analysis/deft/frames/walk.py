"""The plain walk: every trigger after the previous frame's, in order, each with the inputs at its arrival.

Until the module answers: a plain replay of a module answering each
trigger; the cycles that answered nothing are stepped too (their state
counts). Its frames are known once it has been stepped (extraction steps
it); its way is a rule of ``FRAME_RULES`` with no hook.
"""

from __future__ import annotations

from collections.abc import Mapping

from astaa_deft.analysis.deft.frames.rule import FrameRule, register
from astaa_deft.analysis.deft.frames.streams import Candidate, Stream, frame_at

WALK = "plain walk"


def plain_walk(streams: Mapping[str, Stream], trigger: str, previous: Mapping[str, int]) -> Candidate | None:
    """The plain walk's candidate (its first frame: the trigger after the previous frame's), or None."""
    first = previous.get(trigger, -1) + 1
    if first >= len(streams[trigger].times):
        return None
    choice = frame_at(streams, trigger, first, streams[trigger].times[first], previous, absent=True)
    if choice is None:
        return None
    return Candidate(frame_time=streams[trigger].times[first], choice=choice, patterns=frozenset({(WALK, ())}),
                     walk=True)


register(FrameRule(name=WALK, order=0))
