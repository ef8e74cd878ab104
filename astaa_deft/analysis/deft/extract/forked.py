"""The forked search: an output's candidates stepped in forked copies of the module, with learned time limits."""

from __future__ import annotations

import copy
import functools
import math
import time
from collections.abc import Callable, Sequence
from typing import Any, TypeVar

from astaa_deft.analysis.deft.extract.judging import NEAR_MISS_M, Expected, Judged, as_logged, decoded, judged, text_of
from astaa_deft.analysis.deft.extract.recorded import recorded_cycle_s
from astaa_deft.analysis.deft.extract.run import Run
from astaa_deft.analysis.deft.extract.speculation import Speculation, step_first_here, step_in_turn
from astaa_deft.analysis.deft.fork_replay import (
    candidate_limit,
    in_two_forks,
)
from astaa_deft.analysis.deft.frames import Candidate, frame_at
from astaa_deft.analysis.deft.replay import trajectory_points
from astaa_deft.analysis.deft.validator import Comparison

# One candidate stepped: (its comparison, equal to the recorded output field for field, its step's CPU seconds).
Outcome = tuple[Comparison, bool, float, tuple[dict[str, int], ...] | None]  # … for a plain walk: its frames

StepOutcome = TypeVar("StepOutcome")  # what stepping one candidate gives


def decide_forked(run: Run, out_index: int, options: list[Candidate], expected: Expected, *, capped: bool,
                  window: float, expensive: bool) -> None:
    """Search the options in forked copies with their time limits; keep the best and learn from it."""
    cfg, result, outputs = run.cfg, run.result, run.recorded.outputs
    output, skew = outputs[out_index], int(cfg.skew_ms * 1e6)
    full_limit = candidate_limit(recorded_cycle_s(run.recorded, out_index))
    limit = run.memory.budget.neighbour_limit(full_limit) if expensive else run.memory.budget.limit(window, full_limit)
    searched = _search_forked(run, options, expected, limit_s=limit, full_limit_s=full_limit, cheap=not expensive,
                  until_ns=output.log_time + skew)
    if searched is None:
                  run.report(out_index, "no candidate frame decodes or finishes within its time limit")
                  return
    cand, judged, step_s = searched
    within = judged.comparison.within(cfg.threshold)
    result.capped += capped and not within and not 0.0 < judged.comparison.distance <= NEAR_MISS_M
    # A frame within floating-point noise (forked copies of a module not bit-stable across a fork) teaches
    # the search as a reproduced one does: it is the right frame, the suite's own run confirms it.
    if within or judged.comparison.distance <= NEAR_MISS_M:
                  run.memory.learn(cand, step_s, window, expensive)
                  run.last_step_s = step_s
                  run.misses_in_row = 0
    else:
                  run.misses_in_row += 1
    run.keep(out_index, cand, judged)
    if 0.0 < judged.comparison.distance <= NEAR_MISS_M and result.copies_differ is None:
                  _measure_copies(run, cand, full_limit)


def _measure_copies(run: Run, cand: Candidate, limit_s: float) -> None:
    """Step two copies of the module's state on one frame (forked copies, or deep copies where the search
    made those) and record how far apart their answers are: whether the state survives copying is then
    measured, not guessed. The state carried on is untouched (forks), or a deep copy (as in that search)."""
    if run.speculation.following is not None or not run.planner.can_snapshot:
        return  # a shadow leaves it to the runner; a process replay cannot copy its module
    frame = as_logged(run.recorded.frame(cand.choice))
    pair: tuple[Any, Any] | None
    if run.search is not None:
        pair = in_two_forks(lambda: run.planner.step(frame), limit_s)
    else:
        planner = run.planner
        kept = planner.snapshot()
        answers: list[Any] = []
        for _ in range(2):
            planner.restore(copy.deepcopy(kept))
            try:
                answers.append(planner.step(frame))
            except Exception:  # the module's failure on a frame is data, not a measurement
                answers.append(None)
        planner.restore(kept)
        pair = None if None in answers else (answers[0], answers[1])
    if pair is None:
        return
    first, second = pair
    cfg = run.cfg
    reference = Expected(first, trajectory_points(first, cfg.trajectory) if cfg.trajectory is not None else [],
                         text_of(first))
    cmp, exact = judged(cfg, second, reference)
    run.result.copies_differ = 0.0 if exact else cmp.distance


def _walk(run: Run, start: Candidate, expected: Expected, until_ns: int) -> Outcome:
    """The plain walk (frames.walk) stepped: each trigger after the previous frame's at its own time until the
    module answers; that answer judged, the frames stepped carried in the outcome."""
    cfg, recorded = run.cfg, run.recorded
    times = recorded.streams[cfg.trigger].times
    previous = dict(run.previous)
    walked: list[dict[str, int]] = []
    started = time.process_time()
    replayed: Any = None
    index = start.choice[cfg.trigger]
    while index < len(times) and times[index] <= until_ns and replayed is None:
        choice = frame_at(recorded.streams, cfg.trigger, index, times[index], previous, absent=True)
        if choice is None:
            break
        frame = as_logged(recorded.frame(choice, fresh=True))
        try:
            replayed = run.planner.step(frame)
        except Exception as exc:  # the module's crash on a frame is data
            replayed = {"__replay_error__": f"{type(exc).__name__}: {exc}"}
        walked.append(choice)
        previous = choice
        index += 1
    step_s = time.process_time() - started
    if replayed is None:
        return Comparison(math.inf, math.inf, 0, "no answer"), False, step_s, tuple(walked)
    return (*judged(cfg, replayed, expected), step_s, tuple(walked))


def _search_forked(run: Run, options: Sequence[Candidate], expected: Expected, *, limit_s: float,
                   full_limit_s: float, cheap: bool, until_ns: int = 0) -> tuple[Candidate, Judged, float] | None:
    """(candidate, its judgement, its step's CPU seconds) kept for one output, in the process that carries
    on; or None. Candidates cut by ``limit_s`` run again under ``full_limit_s`` if no other is accepted.
    A ``cheap`` output's candidates are stepped right here, one after another (see :func:`step_in_turn`)."""
    planner, cfg, result, speculation = run.planner, run.cfg, run.result, run.speculation
    assert run.search is not None
    search = run.search
    t0 = time.perf_counter()
    decodes = [all(run.recorded.decode(name, idx) is not None for name, idx in cand.choice.items())
               for cand in options]
    result.reconstruction_seconds += time.perf_counter() - t0

    def run_candidate(index: int) -> Outcome | None:
        if options[index].walk:
            return _walk(run, options[index], expected, until_ns)
        if not decodes[index]:
            return None
        frame = decoded(run.recorded.frame(options[index].choice, fresh=True))
        if frame is None:
            return None
        started = time.process_time()  # CPU time, as the limits count it: the load does not count
        try:
            replayed = planner.step(frame)
        except Exception as exc:  # the planner under test may crash on a frame: that is data
            replayed = {"__replay_error__": f"{type(exc).__name__}: {exc}"}
        step_s = time.process_time() - started
        return (*judged(cfg, replayed, expected), step_s, None)

    def accepted(outcome: Outcome | None) -> bool:
        """Within θ; and field for field while the outputs before were (else the closest is kept)."""
        return outcome is not None and outcome[0].within(cfg.threshold) and (
            outcome[1] or not speculation.expect_exact)

    def settles(outcome: Outcome) -> bool:
        """No other candidate can do better: the output reproduced field for field, or (outputs not expected
        field for field) within floating-point noise of it — the right frame on a planner not bit-stable."""
        cmp, exact = outcome[0], outcome[1]
        return (exact and cmp.within(cfg.threshold)) or (
            not speculation.expect_exact and 0.0 < cmp.distance <= NEAR_MISS_M)

    t1 = time.perf_counter()
    kept, in_vain = _step_here(len(options), run_candidate,
                               lambda outcome: accepted(outcome) or (outcome is not None and settles(outcome)),
                               speculation, cheap=cheap, limit_s=limit_s)
    # The forked search tries those not tried in turn first (they were wrong, but may be the closest).
    others = [i for i in range(len(options)) if i not in in_vain]
    known = all(outcome is not None for outcome in in_vain.values())
    rounds = [others, sorted(in_vain)] if known and in_vain and others else [others + sorted(in_vain)]
    # Those tried in vain are stepped again only if none of the others comes as close (their outcome is known;
    # the kept candidate's state is needed): a module that has left the recorded state costs a step less.
    rival = min((outcome[0].distance for outcome in in_vain.values() if outcome is not None), default=math.inf) \
        if len(rounds) > 1 else math.inf  # (two rounds: every outcome tried in vain is known)
    for order in rounds if kept is None else ():
        speculation.let_go()  # the search's winner carries on: it must not inherit the shadow's pipe
        tried = search.search(len(order), functools.partial(_nth, order, run_candidate), accepted=accepted,
                              closeness=lambda r: r[0].distance, limit_s=limit_s,
                              settles=lambda r: settles(r) or _forked_near(r), retry_limit_s=full_limit_s,
                              rival=rival if order is others else math.inf)
        kept = None if tried is None else (order[tried.index], tried.result)
        if kept is not None:
            break
    result.planner_seconds += time.perf_counter() - t1
    index, outcome = kept if kept is not None else (0, None)
    if outcome is None:
        return None
    cmp, exact, step_s, walked = outcome
    speculation.expect_exact = exact
    tries = index + 1 if cmp.within(cfg.threshold) or 0.0 < cmp.distance <= NEAR_MISS_M else len(options)
    cand = options[index]
    if walked:  # the plain walk: the frames it stepped, the last answering
        cand = Candidate(frame_time=run.recorded.streams[cfg.trigger].times[walked[-1][cfg.trigger]],
                         choice=walked[-1],
                         patterns=cand.patterns, silent=tuple(walked[:-1]))
    return cand, Judged(cmp, exact, tries), step_s


def _step_here(count: int, run: Callable[[int], Outcome | None], keeps: Callable[[Outcome | None], bool],
               speculation: Speculation, *, cheap: bool, limit_s: float
               ) -> tuple[tuple[int, Outcome | None] | None, dict[int, Outcome | None]]:
    """An output's candidates stepped in this process before any fork: a ``cheap`` output's (or a lone
    candidate) in turn (:func:`step_in_turn`), an expensive output's first one under ``limit_s`` of CPU time
    (:func:`step_first_here`). (candidate and outcome kept, or None; candidates tried in vain.)"""
    if cheap or count == 1:
        return step_in_turn(count, run, keeps, speculation, in_turn=cheap and count > 1)
    return step_first_here(run, keeps, speculation, limit_s)


def _forked_near(outcome: Outcome) -> bool:
    """A forked candidate within floating-point noise of the output settles its search even while outputs
    reproduce field for field: they do in the replay process that made the module (its own steps), a forked copy
    of a module not bit-stable across a fork never can; the suite's own run judges it on a fresh module."""
    return 0.0 < outcome[0].distance <= NEAR_MISS_M


def _nth(order: Sequence[int], run: Callable[[int], StepOutcome], k: int) -> StepOutcome:
    """``run`` on the ``k``-th candidate of ``order``."""
    return run(order[k])
