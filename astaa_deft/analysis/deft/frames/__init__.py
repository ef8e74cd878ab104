"""Frame reconstruction: which input messages did the module consume for an output?

Pure logic over time-sorted message streams (times are the recorder's
receive times, ns). For an output logged at t_P (an :class:`OutputContext`):

- the trigger is a trigger-channel message at or before t_P and after the
  previous frame's trigger, placed by the frame rules (``frames/rules/``,
  one module each, on the ``FRAME_RULES`` registry) in their order: the
  newest first (a module that keeps up), the newest when the previous cycle
  ended, a busy module's, the first after the previous output (a module
  dropping triggers while busy, or taking the oldest of a bounded queue),
  the oldest not yet used (a module that lags behind answers them in
  order), then the ones between; a first output may answer the first
  triggers of the log (a first cycle is often the slowest);
- the frame time t_F lies between the trigger (t_T) and t_P; each other
  input is the newest message at or before t_F, never older than the one
  used in the previous frame (per channel); a channel's lone message is
  reused for every frame;
- each distinct frame that some t_F yields is a candidate; they come in the
  rules' order of their triggers, and per trigger t_F = t_T first (modules
  snapshot inputs when triggered), then later t_F in time order, then t_F
  just before messages the recorder logged up to `lookback` before the
  trigger (delivery jitter). Frames read at a time (``read_at``) come
  before them all, whole-frame rules (the inputs as logged) after.

A candidate carries every way it was derived (rule, offsets): the search
learns which way wins in a run (``search_policy``). Everything is bisection
over sorted arrays: a frame costs microseconds.
"""

from __future__ import annotations

from collections.abc import Sequence

from astaa_deft.analysis.deft.frames.context import FIRST_OUTPUT_TRIGGERS, OutputContext
from astaa_deft.analysis.deft.frames.per_trigger import trigger_candidates, trigger_frame
from astaa_deft.analysis.deft.frames.read_at import frame_read_at, read_times
from astaa_deft.analysis.deft.frames.rule import (
    FRAME_RULES, FrameRule, Trigger, first_output_ways, ordered, ways_where,
)
from astaa_deft.analysis.deft.frames.streams import (
    Candidate, Pattern, Stream, frame_at, frames_of_trigger, merged, newest_at_or_before,
)
from astaa_deft.analysis.deft.frames.walk import plain_walk


def candidates(ctx: OutputContext) -> list[Candidate]:
    """Distinct candidate frames for the output, most likely first (see the module's docstring)."""
    if ctx.newest < 0:
        return []
    found = [c for c in (frame_read_at(ctx.streams, ctx.trigger, t, ctx.previous, rule=way) for t, way in ctx.read_at)
             if c is not None]
    rules = ordered()
    for index, ways in placed_triggers(ctx, rules).items():
        found += frames_of_trigger(ctx.streams, ctx.trigger, index, ctx.output_ns, previous=ctx.previous,
                                   lookback_ns=ctx.lookback_ns, ways=ways)
    found += [c for rule in rules if rule.frame is not None and (c := rule.frame(ctx)) is not None]
    return merged(found)


def placed_triggers(ctx: OutputContext, rules: Sequence[FrameRule] | None = None) -> dict[int, set[str]]:
    """The triggers the rules place (default: every registered rule), in their order, each with the ways that
    name it."""
    placed: dict[int, set[str]] = {}
    for rule in ordered() if rules is None else rules:
        for index, way in rule.triggers(ctx) if rule.triggers is not None else ():
            ways = placed.setdefault(index, set())
            if way is not None:
                ways.add(way)
        if rule.names_rest is not None:
            rest = rule.names_rest(ctx)
            for ways in placed.values():
                if not ways:
                    ways.add(rest)
    return placed


__all__ = [
    "FIRST_OUTPUT_TRIGGERS", "FRAME_RULES", "Candidate", "FrameRule", "OutputContext", "Pattern", "Stream", "Trigger",
    "candidates", "first_output_ways", "frame_at", "frame_read_at", "merged", "newest_at_or_before",
    "placed_triggers", "plain_walk", "read_times", "trigger_candidates", "trigger_frame", "ways_where",
]
