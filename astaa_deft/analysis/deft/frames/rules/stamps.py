"""A synchroniser on header stamps: each candidate trigger with every other input's nearest-stamp message it had.

A module pairing its inputs by their header stamps (ROS message_filters'
ApproximateTime and its like) takes, per other input, the message whose
stamp is nearest the trigger's, whenever it was logged. For each trigger
the other rules' frames answer, the frame such a module would pair from
the messages it had when the previous output went out (a busy module's
cycle start) and when this one did. Its ways are (the trigger's rule,
SYNCED): learned with the trigger's rule, never for every trigger at once.

Only where a wrong frame costs a step (``costly_only``: an expensive
output's search), and tried only once the run shows a synchroniser
(``search_policy.SearchMemory.stamps``): a synced frame is most often a
trigger's own frame as well, and tried on every module it came second where
the first missed (drop_latched, drop_several_slow1hz: +10-14 % of the time).
"""

from __future__ import annotations

from bisect import bisect_right
from collections.abc import Iterable, Iterator, Sequence

from astaa_deft.analysis.deft.frames.context import OutputContext
from astaa_deft.analysis.deft.frames.rule import FrameRule, register
from astaa_deft.analysis.deft.frames.streams import Candidate

STAMPS = "stamps"
SYNCED = ((STAMPS, 0),)  # the offsets part of a synced frame's ways: (trigger rule, SYNCED)


def synced(ctx: OutputContext, t_index: int, *, until_ns: int, rules: Iterable[str]) -> Candidate | None:
    """The frame of a module synchronising on stamps: trigger ``t_index`` and, per other input, the message
    logged by ``until_ns`` (not older than the previous frame's) whose stamp (``ctx.stamp_of(channel,
    index)``, None: it has none) is nearest the trigger's — a tie, the newer; an input with no such message
    left out (absent). ``rules``: how the trigger was chosen. None when the trigger has no stamp (or the
    context reads no stamps)."""
    streams, trigger, previous, stamp_of = ctx.streams, ctx.trigger, ctx.previous, ctx.stamp_of
    if stamp_of is None:
        return None
    target = stamp_of(trigger, t_index)
    if target is None:
        return None
    choice = {trigger: t_index}
    for name, stream in streams.items():
        if name == trigger:
            continue
        best: tuple[float, int] | None = None
        for index in range(bisect_right(stream.times, until_ns) - 1, max(previous.get(name, 0), 0) - 1, -1):
            stamp = stamp_of(name, index)
            if stamp is not None and (best is None or abs(stamp - target) < best[0]):
                best = (abs(stamp - target), index)
        if best is not None:
            choice[name] = best[1]
    return Candidate(frame_time=streams[trigger].times[t_index], choice=choice,
                     patterns=frozenset((rule, SYNCED) for rule in rules))


def of_found(ctx: OutputContext, found: Sequence[Candidate]) -> Iterator[Candidate]:
    if ctx.stamp_of is None:
        return
    rules: dict[int, set[str]] = {}
    for cand in found:
        if ctx.trigger in cand.choice:
            rules.setdefault(cand.choice[ctx.trigger], set()).update(rule for rule, _ in cand.patterns)
    bounds = ([ctx.previous_output_ns] if ctx.previous_output_ns is not None else []) + [ctx.output_ns]
    for t_index, named in rules.items():
        for until in bounds:
            paired = synced(ctx, t_index, until_ns=until, rules=named)
            if paired is not None:
                yield paired


register(FrameRule(name=STAMPS, order=120, of_found=of_found, costly_only=True))
