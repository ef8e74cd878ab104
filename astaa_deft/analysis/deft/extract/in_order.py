"""The in-order search: each recorded output decided in turn, the module carried on from the frame kept.

Candidates come from the frame rules (``frames.candidates``), ordered by what
earlier outputs taught (``search_policy``); an output is stepped here from
deep copies of the state, or handed to the forked search (``forked``).
"""

from __future__ import annotations

import copy
import os
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from typing import Any

from astaa_deft.analysis.deft.extract.forked import decide_forked
from astaa_deft.analysis.deft.extract.judging import Expected, Judged, decoded, judged, text_of
from astaa_deft.analysis.deft.extract.recorded import Recorded
from astaa_deft.analysis.deft.extract.records import Decided, ExtractedFrame, Extraction, OnOutput
from astaa_deft.analysis.deft.extract.run import Run
from astaa_deft.analysis.deft.fork_replay import (
    ForkedSearch,
)
from astaa_deft.analysis.deft.frames import Candidate, OutputContext, Stream, candidates, plain_walk, read_times
from astaa_deft.analysis.deft.replay import ReplayPlanner, trajectory_points
from astaa_deft.analysis.deft.search_policy import EXPENSIVE_TRIES, nearest_first
from astaa_deft.analysis.deft.validator import Comparison
from astaa_deft.engine.spec.replay_section import ReplayModule
from astaa_deft.io.codecs.base import DecodeError
from astaa_deft.io.log.reader import LogContents, LoggedMessage
from astaa_deft.model.sut import Spec

# A cheap output's candidates are stepped in the runner itself, one after another, a shadow copy following
# one output behind (see fork_replay.shadow), when the recorded planner answered within this window: a cheap
# cycle, whose wrong frames are cheap too (a wrong frame stepped in the runner cannot be cut). Forking a worker
# per candidate costs as much as such a step (docs/performance.md, "analysis").
SPECULATE_MAX_WINDOW_S = 0.05


FIRST_OUTPUT_TRIES = 32  # a run's first expensive output tries up to this many candidates (_first_output_widened)
FIRST_OUTPUT_REACH = 40  # … of the triggers up to this many back from its newest
DEEP_MISSES = 4  # outputs in a row not reproduced after which only the likeliest candidate is stepped
NARROWING = 2  # … before that, each output not reproduced divides the candidates tried by 2 ** NARROWING


AGAIN = "again"  # the previous output's frame again: the next message of one cycle


def extract_in_order(log: LogContents, spec: Spec, planner: ReplayPlanner, progress: OnOutput, *,
                     search: ForkedSearch | None, cfg: ReplayModule, resume: Sequence[Decided] = (),
                     made_here: bool = False) -> Extraction:
    """A frame per recorded output, in order (see :func:`extract`); ``search`` None: no forking.

    In a forked search, the process that returns is the one holding the
    state after the last output kept; a shadow that was told to keep the
    last output exits here instead (the runner reports). ``made_here``:
    ``planner`` was made fresh in this process (its in-order steps are the
    suite's own run until a fork takes over).
    """
    recorded = Recorded.read(log, spec, cfg)
    run = Run(planner=planner, cfg=cfg, recorded=recorded, search=search, progress=progress,
              result=Extraction(outputs=len(recorded.outputs)),
              born=os.getpid() if made_here and search is not None else None)
    for out_index in range(len(recorded.outputs)):
        _extract_output(run, out_index, resume[out_index] if out_index < len(resume) else None)
    speculation, result = run.speculation, run.result
    if speculation.following is not None:  # a shadow told KEEP on the last output: the runner reports, not it
        os._exit(0)
    if search is not None:  # the counters as the last runner holds them (each winner takes them over)
        speculation.let_go()
        result.candidates_cut, result.cut_retried, result.retried_kept = search.cut, search.retried, search.retried_kept
        result.first_stepped_in_runner, result.first_missed_in_runner = speculation.hits, speculation.misses
    return result


def _extract_output(run: Run, out_index: int, before: Decided | None) -> None:
    """Decide output ``out_index``: step it as ``before`` decided it (resumed), or search its candidates."""
    t0 = time.perf_counter()
    cfg, result, recorded, planner = run.cfg, run.result, run.recorded, run.planner
    outputs, skew = recorded.outputs, int(cfg.skew_ms * 1e6)
    output = outputs[out_index]
    generic = _generic_candidates(run, out_index)
    previous_output = outputs[out_index - 1] if out_index else None
    window = _recorded_window_s(recorded.streams[cfg.trigger], generic, output, previous=previous_output,
                                skew_ns=skew) if generic else 0.0
    if before is not None:
        _step_resumed(run, out_index, before, generic=generic, window=window)
        return
    # An expensive output (forked search, a recorded window past a cheap cycle's): every wrong frame costs
    # a planner step, so the frames nearest their trigger come first and only the first few are tried.
    expensive = run.search is not None and window > SPECULATE_MAX_WINDOW_S
    first = not run.previous and planner.can_snapshot
    options, capped = run.memory.order(generic, expensive=expensive, first=first, trigger=cfg.trigger)
    if first and expensive:
        options, capped = _first_output_widened(run, out_index, options)
    if run.misses_in_row and run.search is not None:
        # Outputs in a row not reproduced: the module's state has most likely left the recorded one (a warm
        # start carries the first error on), and no frame will reproduce the next. The search narrows (8, 2,
        # then the likeliest only) until an output reproduces again: a plain replay's cost, not a search's.
        # (The plain walk comes on top: a module with counters finds the recorded state again by it.) Narrowing
        # 8, 4, 2, 1 cost 10-15 % more on the zoo's members that leave their state and reproduced no more.
        budget = max(1, EXPENSIVE_TRIES >> (NARROWING * (run.misses_in_row - 1)))
        capped = capped or len(options) > budget
        options = options[:budget]
    result.reordered += options[:1] != generic[:1]
    t1 = time.perf_counter()
    result.reconstruction_seconds += t1 - t0
    expected = _expected(run, out_index)
    result.validation_seconds += time.perf_counter() - t1
    options, capped = _put_first(run, out_index, options, expected, capped=capped)
    if not options:
        run.report(out_index, "an input had no message yet")
        return
    if not planner.can_snapshot:
        options = options[:1]
    if run.search is None:
        kept = _search_in_process(run, options, expected)
        if kept is None:
            run.report(out_index, "no candidate frame decodes")
            return
        run.keep(out_index, *kept)
        return
    decide_forked(run, out_index, options, expected, capped=capped, window=window, expensive=expensive)


def _generic_candidates(run: Run, out_index: int) -> list[Candidate]:
    """The output's candidate frames from the log alone, most likely first (:func:`.frames.candidates`)."""
    return candidates(_context(run, out_index))


def _first_output_widened(run: Run, out_index: int, likeliest: list[Candidate]) -> tuple[list[Candidate], bool]:
    """A run's first expensive output: its likeliest candidates, then up to FIRST_OUTPUT_TRIES in all of every
    trigger since the log's first (FIRST_OUTPUT_REACH back), frames at their trigger's own time first.

    Nothing is learned yet, and a module carrying its state (a warm start) carries a miss here into every output
    after it; the others are stepped only while none of the likeliest reproduces it (a search stops at the first
    that settles it). timer_heavy_noisy under load: its first cycle (a timer tick between two triggers) ended
    900 ms after the first trigger, its frame 14 triggers before the newest — out of a first output's usual reach.
    """
    ctx = replace(_context(run, out_index), first_reach=FIRST_OUTPUT_REACH)
    tried = [dict(c.choice) for c in likeliest]
    wider = [c for c in nearest_first(candidates(ctx)) if dict(c.choice) not in tried]
    wider.sort(key=lambda c: min((max((abs(offset) for _, offset in offsets), default=0)
                                  for _, offsets in c.patterns), default=0))  # sorted() is stable
    options = likeliest + wider[:max(0, FIRST_OUTPUT_TRIES - len(likeliest))]
    return options, len(wider) > FIRST_OUTPUT_TRIES - len(likeliest)


def _context(run: Run, out_index: int) -> OutputContext:
    """What the frame rules know of output ``out_index`` (:class:`.frames.OutputContext`)."""
    cfg, recorded = run.cfg, run.recorded
    outputs, skew = recorded.outputs, int(cfg.skew_ms * 1e6)
    output = outputs[out_index]
    # A plain replay's frame (everything logged by the output), the cycle's start (the output's time minus the
    # step's measured cost), the previous output's time (a busy module starts a cycle as it ends one).
    read_at = read_times(recorded.streams, cfg.trigger, run.previous, output_ns=output.log_time,
                         previous_output_ns=outputs[out_index - 1].log_time if out_index else None,
                         step_ns=None if run.last_step_s is None else int(run.last_step_s * 1e9))
    return OutputContext(
        streams=recorded.streams, trigger=cfg.trigger, output_ns=output.log_time + skew, previous=run.previous,
        lookback_ns=int(cfg.lookback_ms * 1e6),
        previous_output_ns=outputs[out_index - 1].log_time + skew if out_index else None, read_at=read_at,
        module_started_in_log=recorded.module_started_in_log, skew_ns=skew,
        earlier_outputs_ns=[o.log_time for o in reversed(outputs[max(0, out_index - 4):out_index - 1])])


def _put_first(run: Run, out_index: int, options: list[Candidate], expected: Expected, *,
               capped: bool) -> tuple[list[Candidate], bool]:
    """The search's order: the plain walk, the previous frame again, a declared frame first where they apply;
    the likeliest alone after a long run of misses. Returns the options and whether they were cut."""
    cfg, recorded, planner = run.cfg, run.recorded, run.planner
    outputs, skew = recorded.outputs, int(cfg.skew_ms * 1e6)
    output = outputs[out_index]
    result = run.result
    walk = plain_walk(recorded.streams, cfg.trigger, run.previous) if (
        run.search is not None and cfg.trajectory is None and planner.can_snapshot) else None
    if walk is not None and walk.frame_time > output.log_time + skew:
        walk = None  # no trigger came since the previous frame's (a module publishing several messages a cycle)
    if walk is not None:  # a module (not the planner): the plain walk first, unless another way won more
        first = bool(options) and run.memory.winning.score(options[0]) > run.memory.winning.score(walk)
        options = [*options[:1], walk, *options[1:]] if first else [walk, *options]
    if out_index and run.previous and output.log_time - outputs[out_index - 1].log_time <= skew:
        # An output right after the previous one (within the skew): most likely the next message of the same
        # cycle (a module publishing several a cycle answers it whatever the frame). The previous frame again,
        # first: a frame with a newer trigger would take that trigger from the cycle that answers it.
        again = Candidate(frame_time=outputs[out_index - 1].log_time, choice=dict(run.previous),
                          patterns=frozenset({(AGAIN, ())}))
        options = [again] + [c for c in options if dict(c.choice) != run.previous]
    declared = recorded.declared(cfg, expected.message, run.previous, output.log_time + skew)
    if declared is not None:  # the module said which inputs it used: that frame first, checked by replay
        result.declared += 1
        options = [declared] + [c for c in options if dict(c.choice) != dict(declared.choice)]
    if run.misses_in_row > DEEP_MISSES and run.search is not None:
        # A long run of outputs not reproduced (a module with counters finds the recorded state again within a
        # few by the plain walk; a warm start never does): the likeliest candidate alone, walk or not — one
        # step in the replay process, nothing forked, a plain replay's cost.
        capped = capped or len(options) > 1
        options = options[:1]
    return options, capped


def _step_resumed(run: Run, out_index: int, before: Decided, *, generic: Sequence[Candidate], window: float
                  ) -> None:
    """An output decided before the extraction was resumed: stepped once, as then; what it taught is learned
    again."""
    if before.frame is None or before.choice is None:
        run.report(out_index, before.skipped or "skipped")
        return
    run.previous = dict(before.choice)
    recorded = run.recorded
    stepped, step_s, replayed = _step_decided(run.planner, before.frame, run.previous, decode=recorded.fresh,
                                              messages=recorded.messages, output=recorded.outputs[out_index])
    # Judged again, never taken from the state file: a hand-edited verdict would make tests that fail on the
    # run they came from (or drop ones that pass).
    comparison, exact = judged(run.cfg, replayed, _expected(run, out_index))
    stepped = replace(stepped, comparison=comparison, exact=exact, accepted=comparison.within(run.cfg.threshold))
    run.result.frames.append(replace(stepped, index=len(run.result.frames)))
    for cand in generic if before.frame.accepted else ():
        if dict(cand.choice) == run.previous:
            run.memory.learn(cand, step_s, window,
                             expensive=run.search is not None and window > SPECULATE_MAX_WINDOW_S)
    run.report(out_index)


def _expected(run: Run, out_index: int) -> Expected:
    """Recorded output ``out_index`` decoded (a warning in the result when it does not decode)."""
    cfg = run.cfg
    try:
        message = run.recorded.codecs[cfg.output].decode(run.recorded.outputs[out_index].data)
    except DecodeError as exc:
        message = None
        run.result.warnings.append(f"output {out_index}: recorded output does not decode ({exc})")
    points = trajectory_points(message, cfg.trajectory) if cfg.trajectory is not None else []
    return Expected(message, points, text_of(message))


def _search_in_process(run: Run, options: Sequence[Candidate], expected: Expected
                       ) -> tuple[Candidate, Judged] | None:
    """The candidate kept for one output, each stepped here from a deep copy of the state before it: the
    first within θ, else the closest (the planner is left in the state after it); None if none decodes."""
    planner, cfg, result = run.planner, run.cfg, run.result
    # Several candidates: each must start from the same planner state.
    t1 = time.perf_counter()
    start_state = planner.snapshot() if len(options) > 1 else None
    result.planner_seconds += time.perf_counter() - t1
    # (comparison, candidate, equal to the recording, state after it or None if current, tries)
    best: tuple[Comparison, Candidate, bool, object, int] | None = None
    for tries, cand in enumerate(options, start=1):
        t0 = time.perf_counter()
        frame = decoded(run.recorded.frame(cand.choice))
        result.reconstruction_seconds += time.perf_counter() - t0
        if frame is None:
            continue
        t1 = time.perf_counter()
        if tries > 1 and start_state is not None:
            planner.restore(copy.deepcopy(start_state))
        cpu = time.process_time()
        try:
            replayed = planner.step(frame)
        except Exception as exc:  # the planner under test may crash on a frame: that is data
            replayed = {"__replay_error__": f"{type(exc).__name__}: {exc}"}
        # The step's cost in CPU time, as the forked search and the decided steps measure it: the cycle's start
        # it dates (frames.read_at) must not move with this machine's load, as a wall-clock time does (the same
        # loaded log gave 95 or 67 of 109 outputs by the load beside the extraction).
        step_s = time.process_time() - cpu
        t2 = time.perf_counter()
        result.planner_seconds += t2 - t1
        cmp, exact = judged(cfg, replayed, expected)
        t1 = time.perf_counter()
        result.validation_seconds += t1 - t2
        if cmp.within(cfg.threshold):
            best = (cmp, cand, exact, None, tries)
            run.memory.learn(cand)
            run.last_step_s = step_s
            break
        if best is None or cmp.distance < best[0].distance:
            state = planner.snapshot() if start_state is not None else None
            best = (cmp, cand, exact, state, tries)
        result.planner_seconds += time.perf_counter() - t1
    if best is None:
        return None
    cmp, cand, exact, state, _ = best
    if state is not None:
        planner.restore(state)  # carry on from the state the kept frame produced
    tries = len(options) if not cmp.within(cfg.threshold) else best[4]
    return cand, Judged(cmp, exact, tries)


def _step_decided(planner: ReplayPlanner, decided: ExtractedFrame, choice: Mapping[str, int], *,
                  decode: Callable[[str, int], Any], messages: Mapping[str, list[LoggedMessage]],
                  output: LoggedMessage) -> tuple[ExtractedFrame, float, Any]:
    """(the frame, with its messages; the CPU seconds of its step; what the planner replayed) of an output
    decided by the extraction resumed: the planner steps once on it, as the interrupted extraction left it."""
    started = time.process_time()
    replayed = planner.step({name: decode(name, idx) for name, idx in choice.items()})
    step_s = time.process_time() - started
    frame = replace(decided, output=output, inputs={name: messages[name][idx] for name, idx in choice.items()})
    return frame, step_s, replayed


def _recorded_window_s(trigger: Stream, options: list[Candidate], output: LoggedMessage, *,
                       previous: LoggedMessage | None, skew_ns: int) -> float:
    """The longest the recorded planner can have worked on this output: from the later of its earliest
    candidate trigger and its previous output (a busy planner starts as it publishes) to the output."""
    start = min(trigger.times[c.choice[trigger.channel]] for c in options)
    if previous is not None:
        start = max(start, previous.log_time)
    return max(output.log_time + skew_ns - start, skew_ns) * 1e-9
