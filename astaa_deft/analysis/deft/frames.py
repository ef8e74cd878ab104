"""Frame reconstruction: which input messages did the planner consume for an output?

Pure logic over time-sorted message streams (times are the recorder's
receive times, ns). For an output logged at t_P:

- the trigger is a trigger-channel message at or before t_P and after the
  previous frame's trigger: the newest one first (a planner that keeps up),
  then the oldest not yet used (a planner that lags behind its triggers
  answers them in order), then the ones between — the newest at the
  previous output's time right after the newest (a planner busier than its
  trigger period starts a cycle as it ends one); for the first output
  (no previous frame) the oldest is among the `FIRST_OUTPUT_TRIGGERS`
  before it — a first cycle is often the slowest (a planner building its
  state), answering a trigger several periods old;
- the frame time t_F lies between the trigger (t_T) and t_P; each other
  input is the newest message at or before t_F, never older than the one
  used in the previous frame (per channel); a channel's lone message is
  reused for every frame;
- each distinct frame that some t_F yields is a candidate; they are ordered
  by likelihood: t_F = t_T first (planners snapshot inputs when triggered),
  then later t_F in time order, then t_F just before messages the recorder
  logged up to `lookback` before the trigger (the planner may have received
  them after the trigger: delivery jitter).

Everything is bisection over sorted arrays: a frame costs microseconds.
"""

from __future__ import annotations

from bisect import bisect_right
from collections.abc import Mapping, Sequence
from dataclasses import dataclass


FIRST_OUTPUT_TRIGGERS = 10


@dataclass(frozen=True)
class Stream:
    """One channel's messages in receive order: times (ns) ascending."""

    channel: str
    times: Sequence[int]


# How a candidate's trigger was chosen (see :func:`candidates`): the newest at the output, the newest when
# the previous output was logged (a busy planner), the oldest not yet used, one between, or for a first
# output one before the newest — FIRST if it is the first the planner could plan from (every input had a
# message) and the log reaches back to it.
NEWEST, BUSY, OLDEST, BETWEEN, EARLIER, FIRST = "newest", "busy", "oldest", "between", "earlier", "first"
# … or, for a first output, the first trigger in the log when some input had not been heard from by then (a
# module that cycles with an input absent, see frame_at).
FIRST_HEARD = "first heard"
AS_LOGGED = "as logged"  # the newest trigger and the inputs logged before it, whatever the previous frame used
AFTER = "after"  # the first trigger logged after the previous output (a module that drops those while busy)
# … or after the output m before ("after m": the oldest of a queue m - 1 deep), for m up to 1 + QUEUE_DEPTHS.
QUEUE_DEPTHS = 3
AFTER_RULES = frozenset({AFTER} | {f"{AFTER} {m}" for m in range(2, QUEUE_DEPTHS + 2)})
AFTER_JITTER_NS = 1_000_000  # a trigger logged this long before an output may have reached the module after it
PUBLISH_JITTER_NS = 5_000_000  # … or, for a module publishing a while after its cycle ended, this long
# The newest trigger logged before the previous output (AFTER_JITTER_NS before it, without the skew): the one a
# module taking the newest trigger when its cycle ends had then — one logged just before the output (or within
# the skew after it) reached it after that cycle had ended.
CYCLE_END = "cycle end"
# A step this long could not have read its inputs as its output went out: a module this slow that ended a cycle
# with a trigger waiting read the next cycle's inputs then (see read_times).
INSTANT_STEP_NS = 50_000_000


@dataclass(frozen=True)
class Candidate:
    frame_time: int
    choice: Mapping[str, int]  # channel → index into its stream (trigger included)
    # The ways this frame was derived, for learning which way wins in a run: one (trigger rule, offsets)
    # per rule that names its trigger, offsets = each other input's index minus its index in the frame at
    # the trigger's own time (-1: the planner got that input's newest message only after the trigger).
    patterns: frozenset[tuple[str, tuple[tuple[str, int], ...]]] = frozenset()
    # Frames the module is stepped on first, each a cycle that published nothing (its state moved all the
    # same): the recorder has no output of them, the output comes after them (see WALK).
    silent: tuple[Mapping[str, int], ...] = ()
    walk: bool = False  # the plain walk (see WALK): its frames are known once stepped


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


def candidates(streams: Mapping[str, Stream], trigger: str, t_p: int, previous: Mapping[str, int],
               lookback_ns: int, previous_output_ns: int | None = None,
               read_at: Sequence[tuple[int, str]] = (), module_started_in_log: bool = False, *,
               skew_ns: int = 0, earlier_outputs_ns: Sequence[int] = ()) -> list[Candidate]:
    """Distinct candidate frames for an output at t_P, most likely first.

    ``previous_output_ns``: when the previous output was logged. A planner
    busier than its trigger period starts its next cycle as it finishes one,
    on the newest trigger then: that trigger comes right after the newest.
    ``read_at``: (time, rule) of frames to try first, each the newest trigger
    and inputs at that time (see :func:`frame_read_at`).
    ``module_started_in_log``: the log began before the module's first
    trigger (the tool started the run): a first output may answer the log's
    first triggers however many came since.
    ``skew_ns``: how much of ``previous_output_ns`` is the recorder's skew
    (the output itself was logged that much earlier). ``earlier_outputs_ns``:
    when the outputs before the previous one were logged (newest first): a
    module taking the oldest of a bounded queue answers the trigger that
    found room when an earlier cycle started (:data:`AFTER` ``m``).
    """
    trig = streams[trigger]
    newest = newest_at_or_before(trig.times, t_p)
    if newest < 0:
        return []
    timed = [c for c in (frame_read_at(streams, trigger, t, previous, rule=rule) for t, rule in read_at)
             if c is not None]
    # The first output (no previous frame) may answer a trigger some periods before the newest.
    oldest = previous[trigger] + 1 if trigger in previous else max(0, newest - FIRST_OUTPUT_TRIGGERS + 1)
    busy = newest_at_or_before(trig.times, previous_output_ns) if previous_output_ns is not None else -1
    # A busy module's cycle ended a little before its output was logged (the output's own delivery): the
    # triggers logged up to ``lookback`` before the previous output may be the newest it had then.
    jitter = [] if previous_output_ns is None else [
        i for i in range(busy - 1, max(oldest, bisect_right(trig.times, previous_output_ns - lookback_ns)) - 1, -1)]
    # A module that drops the triggers coming while it is busy answers the first one after its previous output
    # (logged up to AFTER_JITTER_NS before that output: the module was idle before the recorder logged it); one
    # taking the oldest of a queue m - 1 deep, the first one after the output m before (its cycle freed a place).
    afters: dict[int, set[str]] = {}
    if previous_output_ns is not None:
        for m, t_out in enumerate([previous_output_ns - skew_ns, *earlier_outputs_ns][:QUEUE_DEPTHS + 1], start=1):
            # A trigger logged within the jitter before the output may as well have reached the module while
            # it was still busy (and been dropped): then the first one logged after the output is the answer.
            first = bisect_right(trig.times, t_out - AFTER_JITTER_NS)
            for index in dict.fromkeys((first, bisect_right(trig.times, t_out))):
                if oldest <= index <= newest:
                    afters.setdefault(index, set()).add(AFTER if m == 1 else f"{AFTER} {m}")
    cycle_end = newest_at_or_before(trig.times, previous_output_ns - skew_ns - AFTER_JITTER_NS) if (
        previous_output_ns is not None) else -1
    # A module that publishes a while after its cycle ended (a big message, a loaded machine): the trigger logged
    # up to PUBLISH_JITTER_NS before its output may have come after that end — the one before is then the end's.
    # (slow_planner: a trigger logged 1.2 ms before the output; its one wrong frame, carried by the warm state.)
    publish_end = newest_at_or_before(trig.times, previous_output_ns - skew_ns - PUBLISH_JITTER_NS) if (
        previous_output_ns is not None) else -1
    ends = [i for i in dict.fromkeys((cycle_end, publish_end)) if oldest <= i <= newest]
    # The newest trigger logged before the output itself (not the skew after it): one logged within the skew
    # after the output most likely came after the cycle had started (a plain replay of the output's newest
    # trigger takes this one; drop_cycle_none lost such an output to it).
    unskewed = newest_at_or_before(trig.times, t_p - skew_ns)
    order_of_triggers = list(dict.fromkeys(
        [newest] + ([unskewed] if oldest <= unskewed < newest else [])
        + ends + ([busy] if oldest <= busy < newest else [])
        + list(afters) + jitter
        + ([oldest] if oldest < newest else []) + list(range(oldest + 1, newest))))
    rules: dict[int, set[str]] = {index: set() for index in order_of_triggers}
    rules[newest].add(NEWEST)
    if oldest <= unskewed < newest:
        rules[unskewed].add(NEWEST)
    if oldest <= busy <= newest and busy == cycle_end:  # (one logged after the cycle end is the AFTER trigger)
        rules[busy].add(BUSY)
    for index in jitter:
        if index not in ends:  # those are learned by their own rule (a busy trigger's would win its outputs too)
            rules[index].add(BUSY)
    for index, after_rules in afters.items():
        rules[index] |= after_rules
    for index in ends:
        rules[index].add(CYCLE_END)
    if trigger in previous and oldest <= newest:
        rules[oldest].add(OLDEST)
    for index in order_of_triggers:
        if not rules[index]:
            rules[index].add(BETWEEN if trigger in previous else EARLIER)
    if trigger not in previous and (oldest == 0 or module_started_in_log):
        # A first output may answer the first trigger in the log (a slow first cycle, however many triggers
        # came meanwhile) — the first every input had been heard by, or the very first (some input absent).
        for first, rule in _first_triggers(streams, trigger, newest):
            if first not in rules:
                order_of_triggers.append(first)
            rules.setdefault(first, set()).add(rule)
    found = timed + [cand for t_index in order_of_triggers
             for cand in _for_trigger(streams, trigger, t_index, t_p, previous=previous, lookback_ns=lookback_ns,
                                         rules=rules[t_index])]
    # Last, a plain replay's frame: the newest trigger with the inputs as logged before it, even older ones than
    # the previous frame used (that frame may have reproduced its output with an input the module got later).
    as_logged = frame_at(streams, trigger, newest, trig.times[newest], {}, absent=True)
    if as_logged is not None:
        found.append(Candidate(trig.times[newest], as_logged, frozenset({(AS_LOGGED, ())})))
    return merged(found)


def _first_triggers(streams: Mapping[str, Stream], trigger: str, newest: int) -> list[tuple[int, str]]:
    """The triggers a first output may answer: the first every input had been heard by, and the very first."""
    trig = streams[trigger]
    first_plannable = next((i for i in range(0, newest + 1)
                            if frame_at(streams, trigger, i, trig.times[i], {}) is not None), None)
    firsts: list[tuple[int, str]] = [] if first_plannable is None else [(first_plannable, FIRST)]
    if first_plannable != 0:
        firsts.append((0, FIRST_HEARD))
    return firsts


# Frames read at a time rather than derived from a trigger (:func:`frame_read_at`): everything that had
# arrived when the output was logged (a plain replay of the logged inputs in arrival order), at the cycle's
# start (the output's time minus the step's measured cost), when the previous output was logged (a busy
# module starts its next cycle as it ends one).
AT_OUTPUT, AT_START, AT_PREVIOUS = "at output", "at cycle start", "at previous output"
# The plain walk: every trigger after the previous frame's, in order, each with the inputs as they stood at
# its arrival, until the module answers (a plain replay of a module answering each trigger; the cycles that
# answered nothing are stepped too — their state counts). Its frames are known once it has been stepped.
WALK = "plain walk"


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


def plain_walk(streams: Mapping[str, Stream], trigger: str, previous: Mapping[str, int]) -> Candidate | None:
    """The plain walk's candidate (its first frame: the trigger after the previous frame's), or None."""
    first = previous.get(trigger, -1) + 1
    if first >= len(streams[trigger].times):
        return None
    choice = frame_at(streams, trigger, first, streams[trigger].times[first], previous, absent=True)
    if choice is None:
        return None
    return Candidate(streams[trigger].times[first], choice, frozenset({(WALK, ())}), walk=True)


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
    return Candidate(t, choice, frozenset({(rule, ()), (rule, _offsets(streams, trigger, choice, at_trigger))}))


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
            out[seen[key]] = Candidate(first.frame_time, first.choice, first.patterns | cand.patterns)
    return out


def _for_trigger(streams: Mapping[str, Stream], trigger: str, t_index: int, t_p: int, *,
                 previous: Mapping[str, int], lookback_ns: int, rules: set[str]) -> list[Candidate]:
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
        out.append(Candidate(t_f, choice, frozenset((rule, _offsets(streams, trigger, choice, at_trigger))
                                                    for rule in rules)))
    return out


def _offsets(streams: Mapping[str, Stream], trigger: str, choice: Mapping[str, int],
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




# -- per-trigger modules: one frame per trigger message ----------------------------------------


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
