"""Frames over recorded streams: the records every frame rule exchanges and the bisections they are built of.

Pure logic over time-sorted message streams (times are the recorder's
receive times, ns). A frame is a choice of one message per input channel
(channel → index into its stream); every lookup is a bisection over sorted
arrays, so a frame costs microseconds.
"""

from __future__ import annotations

from bisect import bisect_right
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass


@dataclass(frozen=True)
class Stream:
    """One channel's messages in receive order: times (ns) ascending."""

    channel: str
    times: Sequence[int]


# A way a frame was derived: (the rule's way name, each other input's offset from the frame at its trigger's time).
Pattern = tuple[str, tuple[tuple[str, int], ...]]


@dataclass(frozen=True, kw_only=True)
class Candidate:
    frame_time: int
    choice: Mapping[str, int]  # channel → index into its stream (trigger included)
    # The ways this frame was derived, for learning which way wins in a run: one (trigger rule, offsets)
    # per rule that names its trigger, offsets = each other input's index minus its index in the frame at
    # the trigger's own time (-1: the planner got that input's newest message only after the trigger).
    patterns: frozenset[Pattern] = frozenset()
    # Frames the module is stepped on first, each a cycle that published nothing (its state moved all the
    # same): the recorder has no output of them, the output comes after them (see the plain walk).
    silent: tuple[Mapping[str, int], ...] = ()
    walk: bool = False  # the plain walk: its frames are known once stepped


def newest_at_or_before(times: Sequence[int], t: int) -> int:
    """Index of the newest message at or before t, or -1."""
    return bisect_right(times, t) - 1


def frame_at(streams: Mapping[str, Stream], trigger: str, trigger_index: int, t_f: int,
             previous: Mapping[str, int], absent: bool = False) -> dict[str, int] | None:
    """The frame at time t_F; None if some input has had no message yet — unless ``absent``: then that
    input is left out of the frame (the module has not heard from it; the factory contract: an absent
    input is not a key of the frame)."""
    choice = {trigger: trigger_index}
    for name, stream in streams.items():
        if name == trigger:
            continue
        idx = newest_at_or_before(stream.times, t_f)
        idx = max(idx, previous.get(name, -1))  # never older than in the previous frame
        if idx < 0:
            if len(stream.times) == 1:
                idx = 0  # a lone message (sent once, e.g. a route) is the only one there is
            elif absent:
                continue
            else:
                return None
        choice[name] = idx
    return choice


def offsets(streams: Mapping[str, Stream], trigger: str, choice: Mapping[str, int],
            at_trigger: Mapping[str, int]) -> tuple[tuple[str, int], ...]:
    """Each other input's index in ``choice`` minus its index in the frame at the trigger's own time (an input
    absent from both: 0; from one: its distance from having had no message)."""
    out = []
    for name in streams:
        if name == trigger:
            continue
        idx, base = choice.get(name, -1), at_trigger.get(name, -1)
        out.append((name, idx - base))
    return tuple(sorted(out))


def frames_of_trigger(streams: Mapping[str, Stream], trigger: str, t_index: int, t_p: int, *,
                      previous: Mapping[str, int], lookback_ns: int, ways: Iterable[str]) -> list[Candidate]:
    """The frames answering trigger ``t_index`` for an output at t_P, each carrying ``ways``: t_F at the
    trigger first (planners snapshot inputs when triggered), then later t_F in time order (each other input's
    message logged between the trigger and the output), then t_F just before messages the recorder logged up
    to ``lookback`` before the trigger (the planner may have received them after the trigger: delivery
    jitter)."""
    ways = tuple(ways)
    t_t = streams[trigger].times[t_index]
    later: set[int] = set()
    earlier: set[int] = set()
    for name, stream in streams.items():
        if name == trigger:
            continue
        times = stream.times
        lo, hi = bisect_right(times, t_t), bisect_right(times, t_p)
        later.update(times[lo:hi])
        lo_back = bisect_right(times, t_t - lookback_ns - 1)
        # "Just before" each message logged shortly before (or with) the trigger.
        earlier.update(t - 1 for t in times[lo_back:lo])
    out = []
    at_trigger = frame_at(streams, trigger, t_index, t_t, previous, absent=True)
    assert at_trigger is not None  # with absent inputs allowed a frame always exists
    for t_f in [t_t] + sorted(later) + sorted(earlier, reverse=True):
        choice = frame_at(streams, trigger, t_index, t_f, previous, absent=True)
        assert choice is not None
        out.append(Candidate(frame_time=t_f, choice=choice,
                             patterns=frozenset((way, offsets(streams, trigger, choice, at_trigger))
                                                    for way in ways)))
    return out


def merged(found: Sequence[Candidate]) -> list[Candidate]:
    """Distinct frames in first-found order; a frame reached several ways carries all of them."""
    out: list[Candidate] = []
    seen: dict[tuple, int] = {}
    for cand in found:
        key = tuple(sorted(cand.choice.items()))
        if key not in seen:
            seen[key] = len(out)
            out.append(cand)
        else:  # the same frame reached another way: it carries both ways
            first = out[seen[key]]
            out[seen[key]] = Candidate(frame_time=first.frame_time, choice=first.choice,
                                       patterns=first.patterns | cand.patterns)
    return out
