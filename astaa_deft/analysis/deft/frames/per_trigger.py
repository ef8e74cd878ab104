"""Per-trigger modules: one frame per trigger message (a module answering each trigger, at most once).

Pure logic over the recorded streams, like the per-output rules.
"""

from __future__ import annotations

from bisect import bisect_right
from collections.abc import Mapping

from astaa_deft.analysis.deft.frames.streams import Stream, newest_at_or_before


def trigger_frame(streams: Mapping[str, Stream], trigger: str, trigger_index: int,
                  previous: Mapping[str, int]) -> dict[str, int]:
    """A per-trigger frame: the trigger and each other input's newest message at or before it.

    Never older than in the previous frame (per channel); an input that has
    had no message yet is left out (the module has not heard from it).
    """
    t = streams[trigger].times[trigger_index]
    choice = {trigger: trigger_index}
    for name, stream in streams.items():
        if name != trigger:
            idx = max(newest_at_or_before(stream.times, t), previous.get(name, -1))
            if idx >= 0:
                choice[name] = idx
    return choice


def trigger_candidates(streams: Mapping[str, Stream], trigger: str, trigger_index: int,
                       previous: Mapping[str, int], *, lookback_ns: int, answered_at: int | None = None,
                       skew_ns: int = 0) -> list[dict[str, int]]:
    """Per-trigger frames, most likely first: :func:`trigger_frame`; then, per other input, the frame
    with each of its messages logged after the trigger but before the recorded answer (``answered_at``,
    plus ``skew_ns``: the recorder may log the answer before an input the module had — seen under
    load, a planner's burst of trajectories logged 4 ms after the command that used the first), and
    the frame without each of its messages logged up to ``lookback_ns`` before the trigger: the
    recorder and the module each see their own arrival order."""
    first = trigger_frame(streams, trigger, trigger_index, previous)
    out = [first]
    t = streams[trigger].times[trigger_index]
    for name, stream in streams.items():
        if name == trigger or answered_at is None:
            continue
        for idx in range(bisect_right(stream.times, t), bisect_right(stream.times, answered_at + skew_ns)):
            later = {**first, name: idx}
            if later not in out:
                out.append(later)
    for name, stream in streams.items():
        if name == trigger or name not in first:
            continue
        lo = bisect_right(stream.times, t - lookback_ns - 1)
        for idx in range(first[name], max(lo, previous.get(name, -1) + 1) - 1, -1):
            earlier = dict(first)
            if idx - 1 >= 0:
                earlier[name] = idx - 1
            else:
                del earlier[name]
            if earlier not in out:
                out.append(earlier)
    return out
