"""What the frame rules know of one recorded output: :class:`OutputContext`, and the trigger indices rules share.

Pure logic. The context is what the log says around an output logged at
t_P: the input streams, the trigger channel, the frame the previous output
used, when the outputs before were logged, how far the recorder's clock
may be off. The triggers several rules start from (the newest at the
output, the oldest not yet answered, the newest when the previous cycle
ended) are computed here once, lazily, and read by every rule that needs
them.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import cached_property

from astaa_deft.analysis.deft.frames.streams import Stream, frame_at, newest_at_or_before

# A first output (no previous frame) may answer a trigger this many periods before the newest: a first cycle is
# often the slowest (a planner building its state).
FIRST_OUTPUT_TRIGGERS = 10
AFTER_JITTER_NS = 1_000_000  # a trigger logged this long before an output may have reached the module after it
PUBLISH_JITTER_NS = 5_000_000  # … or, for a module publishing a while after its cycle ended, this long


@dataclass(frozen=True, kw_only=True)
class OutputContext:
    """One recorded output as the frame rules see it (times in ns, the recorder's receive times).

    ``output_ns``: t_P, when the output was logged (plus the skew: an input
    logged up to that much after it may have been read). ``previous``: the
    frame the previous output used (channel → index; empty for a first
    output). ``lookback_ns``: how long before its trigger an input message
    may have been logged and still reached the module after it.
    ``previous_output_ns``: when the previous output was logged (None: a
    first output); ``skew_ns`` of it is the recorder's skew.
    ``earlier_outputs_ns``: when the outputs before the previous one were
    logged, newest first. ``read_at``: (time, way) of frames read at a time,
    tried first (see :mod:`.read_at`). ``module_started_in_log``: the log
    began before the module's first trigger (the tool started the run).
    ``first_reach``: how many triggers back from the newest a first output
    may answer (FIRST_OUTPUT_TRIGGERS unless the search widens it).
    """

    streams: Mapping[str, Stream]
    trigger: str
    output_ns: int
    previous: Mapping[str, int]
    lookback_ns: int
    previous_output_ns: int | None = None
    read_at: Sequence[tuple[int, str]] = ()
    module_started_in_log: bool = False
    skew_ns: int = 0
    earlier_outputs_ns: Sequence[int] = ()
    first_reach: int = FIRST_OUTPUT_TRIGGERS

    @property
    def trigger_times(self) -> Sequence[int]:
        return self.streams[self.trigger].times

    @property
    def has_previous(self) -> bool:
        """A previous frame answered a trigger of this channel (not a first output)."""
        return self.trigger in self.previous

    @cached_property
    def newest(self) -> int:
        """The newest trigger at or before the output (-1: none: the output has no candidate)."""
        return newest_at_or_before(self.trigger_times, self.output_ns)

    @cached_property
    def oldest(self) -> int:
        """The oldest trigger the output may answer: the first after the previous frame's; for a first output
        one of the ``first_reach`` before the newest."""
        if self.has_previous:
            return self.previous[self.trigger] + 1
        return max(0, self.newest - self.first_reach + 1)

    def within(self, index: int) -> bool:
        """``index`` is one of the triggers the output may answer (oldest to newest)."""
        return self.oldest <= index <= self.newest

    @cached_property
    def busy(self) -> int:
        """The newest trigger when the previous output was logged (-1: a first output)."""
        if self.previous_output_ns is None:
            return -1
        return newest_at_or_before(self.trigger_times, self.previous_output_ns)

    def newest_before_previous_output(self, jitter_ns: int) -> int:
        """The newest trigger logged ``jitter_ns`` before the previous output (the skew taken off; -1: none)."""
        if self.previous_output_ns is None:
            return -1
        return newest_at_or_before(self.trigger_times, self.previous_output_ns - self.skew_ns - jitter_ns)

    @cached_property
    def cycle_end(self) -> int:
        """The newest trigger logged AFTER_JITTER_NS before the previous output, without the skew: the one a
        module taking the newest trigger when its cycle ends had then."""
        return self.newest_before_previous_output(AFTER_JITTER_NS)

    @cached_property
    def ends(self) -> tuple[int, ...]:
        """The triggers a cycle end may have found (the cycle end's, and the one PUBLISH_JITTER_NS before the
        previous output: a module that publishes a while after its cycle ended), within reach."""
        publish_end = self.newest_before_previous_output(PUBLISH_JITTER_NS)
        return tuple(i for i in dict.fromkeys((self.cycle_end, publish_end)) if self.within(i))

    @cached_property
    def first_plannable(self) -> int | None:
        """The first trigger (up to the newest) every input had been heard by, or None."""
        times = self.trigger_times
        return next((i for i in range(0, self.newest + 1)
                     if frame_at(self.streams, self.trigger, i, times[i], {}) is not None), None)

    @property
    def first_output_reaches_back(self) -> bool:
        """A first output that may answer the log's first triggers (the log reaches back to them)."""
        return not self.has_previous and (self.oldest == 0 or self.module_started_in_log)
