"""Frames read at a time rather than derived from a trigger: the newest trigger and inputs at that time.

Everything that had arrived when the output was logged (a plain replay of
the logged inputs in arrival order), at the cycle's start (the output's
time minus the step's measured cost), when the previous output was logged
(a busy module starts its next cycle as it ends one). :func:`read_times`
says which times, likeliest first; the caller hands them to the
:class:`.OutputContext` (``read_at``), and their frames are tried before
every trigger rule's. Each time's way is a rule of ``FRAME_RULES`` with no
hook: a way a module follows (``likely``).
"""

from __future__ import annotations

from bisect import bisect_right
from collections.abc import Mapping

from astaa_deft.analysis.deft.frames.context import PUBLISH_JITTER_NS
from astaa_deft.analysis.deft.frames.rule import FrameRule, register
from astaa_deft.analysis.deft.frames.streams import Candidate, Stream, frame_at, newest_at_or_before, offsets

AT_OUTPUT, AT_START, AT_PREVIOUS = "at output", "at cycle start", "at previous output"
# A step this long could not have read its inputs as its output went out: a module this slow that ended a cycle
# with a trigger waiting read the next cycle's inputs then (see read_times).
INSTANT_STEP_NS = 50_000_000


def read_times(streams: Mapping[str, Stream], trigger: str, previous: Mapping[str, int], *, output_ns: int,
               previous_output_ns: int | None = None, step_ns: int | None = None) -> list[tuple[int, str]]:
    """(time, rule) of the frames read at a time for an output (see :func:`frame_read_at`), likeliest first.

    ``step_ns``: the module's last measured step. When the previous cycle
    ended with a trigger waiting (one logged before the previous output,
    newer than the previous frame's) and the step is no instant, the module
    started its next cycle as it ended the last: the frame at the previous
    output comes first. Its output was published after that read, so the
    frame just before each input message logged up to PUBLISH_JITTER_NS
    before the previous output follows it (slow_planner: a message logged
    1 ms before the output had reached the module after its read).
    Otherwise a plain replay's frame (everything logged by the output)
    comes first.
    """
    at_output = [(output_ns, AT_OUTPUT)]
    at_start = [] if step_ns is None else [(output_ns - step_ns, AT_START)]
    if previous_output_ns is None:
        return at_output + at_start
    just_before = sorted((t - 1 for name, stream in streams.items() if name != trigger
                          for t in stream.times[bisect_right(stream.times, previous_output_ns - PUBLISH_JITTER_NS):
                                                bisect_right(stream.times, previous_output_ns)]), reverse=True)
    at_previous = [(previous_output_ns, AT_PREVIOUS)] + [(t, AT_PREVIOUS) for t in just_before]
    waiting = newest_at_or_before(streams[trigger].times, previous_output_ns) > previous.get(trigger, -1)
    if waiting and step_ns is not None and step_ns > INSTANT_STEP_NS:
        return at_previous + at_start + at_output
    return at_output + at_start + at_previous


def frame_read_at(streams: Mapping[str, Stream], trigger: str, t: int, previous: Mapping[str, int], *,
                  rule: str) -> Candidate | None:
    """The frame of a module that read, at time ``t``, the newest trigger and the newest message of each
    other input (absent inputs left out); None when no trigger newer than the previous frame's had come."""
    index = newest_at_or_before(streams[trigger].times, t)
    if index < 0 or index <= previous.get(trigger, -1):
        return None
    choice = frame_at(streams, trigger, index, t, previous, absent=True)
    at_trigger = frame_at(streams, trigger, index, streams[trigger].times[index], previous, absent=True)
    if choice is None or at_trigger is None:
        return None
    return Candidate(frame_time=t, choice=choice,
                     patterns=frozenset({(rule, ()), (rule, offsets(streams, trigger, choice, at_trigger))}))


for _order, _way in enumerate((AT_OUTPUT, AT_START, AT_PREVIOUS)):
    register(FrameRule(name=_way, order=_order, likely=True))
