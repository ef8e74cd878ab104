"""Extraction: from a recorded log to validated frames, replaying the planner in order."""

from __future__ import annotations

import contextlib
from bisect import bisect_left, bisect_right
import copy
import functools
import json
import math
import os
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from itertools import pairwise
from typing import Any

from astaa_deft.engine.bus.process_launch import fork_is_safe
from astaa_deft.io.codecs import get_codec
from astaa_deft.io.codecs.base import Codec, DecodeError
from astaa_deft.model.errors import InputError, Problem
from astaa_deft.io.log import records as rec
from astaa_deft.io.log.reader import LogContents, LoggedMessage
from astaa_deft.model.sut import Spec
from astaa_deft.engine.spec.replay_section import ReplayModule
from astaa_deft.analysis.deft.fork_replay import (
    Following, ForkedSearch, Shadow, candidate_limit, cpu_limit, drop, hand_over, in_two_forks, next_word,
    run_supervised, shadow, tell,
)
from astaa_deft.analysis.deft.frames import Candidate, OutputContext, Stream, candidates, frame_at, plain_walk, \
    read_times, trigger_candidates
from astaa_deft.analysis.deft.search_policy import EXPENSIVE_TRIES, SearchMemory
from astaa_deft.analysis.deft.planner_section import planner_of, replay_module_of
from astaa_deft.analysis.deft.replay import ReplayPlanner, StepHang, compare_outputs, trajectory_points, within_limit
from astaa_deft.analysis.deft.validator import Comparison, compare, identical


@dataclass
class ExtractedFrame:
    index: int  # 0-based, in output order
    output: LoggedMessage | None  # None: the module answered this frame with nothing (per-trigger frames)
    trigger_time: int
    frame_time: int
    inputs: dict[str, LoggedMessage]  # channel → the message used
    comparison: Comparison
    accepted: bool
    candidates_tried: int
    exact: bool  # the replayed output message equals the recorded one, field for field


InOrder = tuple[int, Comparison | None, bool]  # (frame index, its comparison or None: no output, exact)


@dataclass(frozen=True)
class Decided:
    """One output as the extraction decided it, passed on as soon as it is (partial results, ``--resume``).

    ``frame`` is None for an output skipped (``skipped`` says why); ``choice``
    names its inputs (channel → index among that channel's messages in the
    log, by log time), which is all a resumed extraction needs to step the
    planner through it again.
    """

    output_index: int
    frame: ExtractedFrame | None
    choice: Mapping[str, int] | None = None
    skipped: str | None = None
    # Frames stepped before ``frame``, cycles that published nothing (no output of their own; their state
    # counts): the suite steps them too. (Not kept for --resume, which steps ``choice`` alone.)
    before: tuple[ExtractedFrame, ...] = ()
    # The suite's own run, done by the replay itself (a forked extraction): frames a fresh module stepped in
    # order — every frame from the first, in the process that made the module — with its judgement of each
    # (frame index, comparison or None for a frame without output, field for field). It covers every frame up
    # to ``frame``; None: it does not, the suite's own run must step them (see SuiteRun).
    in_order: tuple[InOrder, ...] | None = None
    beside: bool = False  # the replay will not do the suite's run (any more): the caller must step every frame


OnOutput = Callable[[int, int, Decided], None]  # (outputs done, outputs in all, the one just decided)


@dataclass
class Extraction:
    frames: list[ExtractedFrame] = field(default_factory=list)
    skipped: list[tuple[int, str]] = field(default_factory=list)  # (output index, why)
    outputs: int = 0
    reconstruction_seconds: float = 0.0  # candidate search + decoding the chosen inputs
    validation_seconds: float = 0.0  # reading the recorded and replayed trajectories, comparing them
    planner_seconds: float = 0.0
    warnings: list[str] = field(default_factory=list)
    recorded_outputs: int | None = None  # per-trigger frames: the outputs in the log (``outputs`` counts frames)
    # The candidate search (forked): candidates stopped by the tight per-candidate limit learned from the
    # accepted steps, those run again under the full limit because no other candidate was accepted, and
    # outputs whose kept frame was one of those.
    candidates_cut: int = 0
    cut_retried: int = 0
    retried_kept: int = 0
    capped: int = 0  # outputs not reproduced by their likeliest candidates (the others not tried: see _extract_output)
    reordered: int = 0  # outputs whose candidates were tried in a learned order other than the generic one
    # Cheap outputs whose first candidate the replay process stepped itself, a shadow copy following:
    # accepted, and not (the shadow then searched the others).
    first_stepped_in_runner: int = 0
    first_missed_in_runner: int = 0
    declared: int = 0  # outputs that named the inputs they used (the spec's provenance), tried first
    # Measured at the first output reproduced within 1e-9 but not exactly: how far apart two copies of the
    # module's state answer one frame (0.0: bit for bit); None: not measured.
    copies_differ: float | None = None
    # The suite run once on its own run beside the search (forked extraction): its tests that failed, (frame
    # index, what); None: not run here (the workflow runs the written suite).
    suite_failures: list[tuple[int, str]] | None = None
    # Frames the search judged off on forked copies that the suite's run (a fresh, unforked module) reproduces.
    confirmed_unforked: int = 0
    # The suite's own run done by the replay itself: frames checked by its in-order steps of a fresh module
    # (the replay process that made it stepped them, no fork had taken over); frames the calling process
    # stepped itself (from the first fork that took over on).
    checked_in_replay: int = 0
    checked_beside: int = 0

    def accepted_at(self, threshold: float) -> int:
        return sum(1 for f in self.frames if f.comparison.distance <= threshold)


def channel_messages(log: LogContents, spec: Spec, names: list[str]) -> dict[str, list[LoggedMessage]]:
    out: dict[str, list[LoggedMessage]] = {}
    for name in names:
        key = spec.channel(name).key
        if key not in log.channels:
            raise InputError(Problem(str(log.path), None, None,
                                     f"the log has no channel '{name}' (key '{key}')",
                                     "record the run with this spec, or check that the log belongs to it"))
        out[name] = sorted(log.on(key), key=lambda m: m.log_time)
    return out


def extract(log: LogContents, spec: Spec, planner: ReplayPlanner, *,
            on_output: OnOutput = lambda done, total, outcome: None,
            jobs: int | Callable[[], int] | None = None, entry: ReplayModule | None = None,
            resume: Sequence[Decided] = (), fresh: Callable[[], ReplayPlanner] | None = None) -> Extraction:
    """Reconstruct and validate a frame per recorded output (per trigger message for a per-trigger module).

    ``entry`` names the module replayed (default: the planner). With ``jobs``
    (an in-process planner on a system that can fork), the candidates of an
    output are tried in forked processes, up to ``jobs`` at a time, from the
    very same planner state (see fork_replay; a callable ``jobs`` is asked
    only then: a per-trigger module steps every frame here); otherwise — or while this
    process runs other Python threads, which a fork must not copy in the
    middle of their work — from deep copies of the planner, one after another.
    ``on_output(outputs done, outputs in all, outcome)`` gets each output
    as soon as it is decided, in order (progress and checkpoints follow it).
    ``resume``: the outputs an earlier extraction of this log decided (in
    order, from the first): their frames are stepped once each, as decided,
    and the search goes on after them.
    ``fresh`` makes a fresh module like ``planner`` (a forked extraction):
    the replay makes its own and its in-order steps are the suite's own run
    (see SuiteRun); without it ``planner`` is forked and this process runs
    the suite beside the search.
    """
    cfg = entry if entry is not None else replay_module_of(spec)
    if cfg.per_trigger:
        return _extract_per_trigger(log, spec, planner, cfg=cfg, progress=on_output)
    if jobs is not None and planner.can_snapshot and fork_is_safe(native_threads_ok=True):
        # The search runs in forked copies; here, beside it, the fresh ``planner`` runs the suite: it steps
        # every frame as it is decided and compares the accepted ones, as `pytest DIR` will.
        workers = jobs() if callable(jobs) else jobs
        follower = SuiteRun(planner, cfg, {name: get_codec(spec.channel(name).encoding)
                                           for name in list(cfg.inputs) + [cfg.output]})

        def on_message(message: tuple[int, int, Decided]) -> None:
            on_output(*message)
            follower.add(message[2])

        def body(send: Callable[[tuple[int, int, Decided]], None]) -> Extraction:
            # A module made here, in the replay process: its steps in this process, in order, are the suite's
            # (a fork of the caller's module is not: a module may answer otherwise in a forked process).
            return _extract(log, spec, fresh() if fresh is not None else planner, lambda *message: send(message),
                            search=ForkedSearch(workers, send), cfg=cfg, resume=resume, made_here=fresh is not None)

        result: Extraction = run_supervised(body, on_message=on_message, idle=follower.step_one)
        follower.finish(result)
        return result
    return _extract(log, spec, planner, on_output, search=None, cfg=cfg, resume=resume)


class SuiteRun:
    """The extracted suite run once on its own run: a fresh module stepped on every frame kept, in order, the
    accepted ones compared with their recorded outputs (what `pytest DIR` does), frame by frame as decided.

    The replay process does that run itself while it can (``Decided.in_order``): it made a fresh module and
    steps the kept frames in order in the process that made it, exactly the suite's run, a forked copy holding
    the state from before each output in case its frame is wrong. Once a frame was not so checked (a fork
    took over) this process steps every frame from the first on its own fresh module, beside the search.
    """

    def __init__(self, planner: ReplayPlanner, cfg: ReplayModule, codecs: Mapping[str, Codec]) -> None:
        self.planner, self.cfg, self.codecs = planner, cfg, codecs
        self.frames: list[ExtractedFrame] = []  # every frame decided, in order (index = position)
        self.stepped = 0  # frames this process's module has stepped, from the first
        self.beside = False  # a frame was not checked by the replay: this process steps them all
        self.failing: dict[int, str] = {}  # frame index → what failed
        self.judged: dict[int, tuple[Comparison, bool]] = {}  # frame index → its comparison here, field for field
        self.in_replay = 0  # frames checked by the replay's own in-order steps

    @property
    def failures(self) -> list[tuple[int, str]]:
        """The tests that failed so far: (frame index, what)."""
        return sorted(self.failing.items())

    def add(self, outcome: Decided) -> None:
        if outcome.frame is None:
            return
        self.frames.extend(outcome.before)
        self.frames.append(outcome.frame)
        self.beside = self.beside or outcome.beside
        self._checked(outcome.in_order)

    def _checked(self, in_order: tuple[InOrder, ...] | None) -> None:
        """The replay's own in-order steps of frames (every frame up to the last named was so stepped)."""
        for index, cmp, exact in in_order or ():
            if cmp is not None:
                self._judge(self.frames[index], cmp, exact)
        if in_order:
            self.in_replay = max(self.in_replay, in_order[-1][0] + 1)

    def finish(self, result: Extraction) -> None:
        """After the replay: its last in-order run applied; any frame it did not check, and this process steps
        every frame (the suite's own run, here); then :meth:`settle`."""
        if self.in_replay < len(self.frames):
            self.beside = True
        while self.step_one():
            pass
        self.settle(result)

    def step_one(self) -> bool:
        """Step the next frame decided, if this process runs the suite (False: none waiting)."""
        if not self.beside or self.stepped >= len(self.frames):
            return False
        frame = self.frames[self.stepped]
        self.stepped += 1
        cfg = self.cfg
        try:
            replayed = self.planner.step({name: self.codecs[name].decode(msg.data)
                                          for name, msg in frame.inputs.items()})
        except Exception as exc:  # the module's failure on a frame is a failing test, not ours
            replayed = {"__replay_error__": f"{type(exc).__name__}: {exc}"}
        if frame.output is not None:
            try:
                recorded = self.codecs[cfg.output].decode(frame.output.data)
            except DecodeError:
                recorded = None
            points = trajectory_points(recorded, cfg.trajectory) if cfg.trajectory is not None else []
            self._judge(frame, *_judged(cfg, replayed, _Expected(recorded, points, _text(recorded))))
        return self.stepped < len(self.frames)

    def _judge(self, frame: ExtractedFrame, cmp: Comparison, exact: bool) -> None:
        self.judged[frame.index] = (cmp, exact)
        if frame.accepted and not cmp.within(self.cfg.threshold):
            self.failing[frame.index] = f"distance {cmp.distance:.3g} (θ = {self.cfg.threshold:g})"
        else:
            self.failing.pop(frame.index, None)

    def settle(self, result: Extraction) -> None:
        """The suite's own run has the last word on each frame kept: a frame the search judged on forked
        copies a little off (a module not bit-stable across a fork) that the suite's fresh module reproduces
        within θ is a test that passes; one the search accepted but the suite's run does not is a failure
        (``result.suite_failures``: an extraction defect)."""
        result.suite_failures = self.failures
        result.checked_beside = self.stepped
        result.checked_in_replay = 0 if self.beside else self.in_replay
        for frame in result.frames:
            judged = self.judged.get(frame.index)
            if judged is not None and not frame.accepted and judged[0].within(self.cfg.threshold):
                frame.comparison, frame.exact, frame.accepted = judged[0], judged[1], True
                result.confirmed_unforked += 1


@dataclass(frozen=True)
class _TriggerModule:
    """What every frame of a per-trigger replay reads: the module, its settings, the decodable inputs."""

    planner: ReplayPlanner
    cfg: ReplayModule
    usable: Mapping[str, list[tuple[LoggedMessage, Any]]]  # channel → (message, decoded), log order


@dataclass(frozen=True)
class _TriggerAnswer:
    """One candidate frame of a trigger as stepped (in the end: the one kept)."""

    comparison: Comparison
    choice: dict[str, int]
    replayed: Any  # the module's answer; None: it answered nothing (or failed)
    error: str | None  # the module crashed or hung on this frame
    state: Any  # the planner state after this frame, or None: the planner's current state
    tries: int


def _extract_per_trigger(log: LogContents, spec: Spec, planner: ReplayPlanner, *, cfg: ReplayModule,
                         progress: OnOutput) -> Extraction:
    """One frame per trigger message, its replayed answer compared with the recorded one.

    Answers pair with the recorded outputs in order; a frame the module
    answers with nothing (``step`` returns None) is plausible when the next
    output was logged after the next trigger. Like the planner's, a frame
    has candidates (each other input with a message logged between the
    trigger and the answer, plus ``skew_ms``, or without its messages logged up to
    ``lookback_ms`` before the trigger: the module may have received them
    in another order than the recorder), tried from the same state, the
    first that matches kept (none: the closest). Inputs that do not decode are dropped, as the module's
    deserialiser would. Triggers logged after the module's last recorded
    output (plus ``skew_ms``) are not replayed: nothing recorded says what
    it answered. The module's crash or hang ends the replay (it answers
    nothing more).
    """
    msgs = channel_messages(log, spec, list(cfg.inputs) + [cfg.output])
    outputs = msgs.pop(cfg.output)
    codecs = {name: get_codec(spec.channel(name).encoding) for name in list(cfg.inputs) + [cfg.output]}
    t0 = time.perf_counter()
    module = _TriggerModule(planner, cfg, _decodable(msgs, codecs))
    streams = {name: Stream(name, [m.log_time for m, _ in items]) for name, items in module.usable.items()}
    result = Extraction(outputs=len(outputs))
    result.reconstruction_seconds += time.perf_counter() - t0
    last = (outputs[-1].log_time if outputs else log_start(log)) + int(cfg.skew_ms * 1e6)
    triggers = [i for i, t in enumerate(streams[cfg.trigger].times) if t <= last]
    result.outputs, result.recorded_outputs = len(triggers), len(outputs)
    times = streams[cfg.trigger].times
    previous: dict[str, int] = {}
    next_output = 0
    for done, t_index in enumerate(triggers, start=1):
        # Answers are paired with recorded outputs in order: a replayed answer is compared with the next
        # output; a frame answered with nothing leaves it to a later frame, which is plausible only when it
        # was logged after the next trigger (a module answers within its cycle, but may lag under load).
        output = outputs[next_output] if next_output < len(outputs) else None
        expected = None
        if output is not None:
            try:
                expected = codecs[cfg.output].decode(output.data)
            except DecodeError as exc:
                result.warnings.append(f"output {next_output}: recorded output does not decode ({exc})")
        nothing_plausible = output is None or t_index + 1 >= len(times) or not _answered_in_turn(
            times, t_index, outputs, next_output)
        t1 = time.perf_counter()
        options = trigger_candidates(streams, cfg.trigger, t_index, previous, lookback_ns=int(cfg.lookback_ms * 1e6),
                                     answered_at=output.log_time if output is not None else None,
                                     skew_ns=int(cfg.skew_ms * 1e6))
        if not planner.can_snapshot:
            options = options[:1]
        start_state = planner.snapshot() if len(options) > 1 else None
        result.reconstruction_seconds += time.perf_counter() - t1
        kept = _answer_trigger(module, options, start_state=start_state, expected=expected,
                               nothing_plausible=nothing_plausible, result=result)
        if kept.state is not None:
            planner.restore(kept.state)  # carry on from the state the kept frame produced
        previous = kept.choice
        answered = kept.replayed is not None and output is not None
        if answered:
            next_output += 1
        within = kept.comparison.within(cfg.threshold)
        result.frames.append(ExtractedFrame(
            index=len(result.frames), output=output if answered else None, trigger_time=times[t_index],
            frame_time=times[t_index], inputs={name: module.usable[name][i][0] for name, i in kept.choice.items()},
            comparison=kept.comparison, accepted=kept.error is None and within,
            candidates_tried=kept.tries if within else len(options),
            exact=kept.error is None and _same(kept.replayed, expected if answered else None)))
        progress(done, len(triggers), Decided(done - 1, result.frames[-1], kept.choice))
        if kept.error is not None:
            result.skipped.append((len(result.frames) - 1, f"the module stopped answering: {kept.error}"))
            break
    return result


def _decodable(messages: Mapping[str, list[LoggedMessage]], codecs: Mapping[str, Codec]
               ) -> dict[str, list[tuple[LoggedMessage, Any]]]:
    """Each channel's messages that decode, with their decoded form (the others are dropped, as the module's
    deserialiser would drop them)."""
    usable: dict[str, list[tuple[LoggedMessage, Any]]] = {}
    for name, stream in messages.items():
        usable[name] = []
        for m in stream:
            with contextlib.suppress(DecodeError):
                usable[name].append((m, codecs[name].decode(m.data)))
    return usable


def _answer_trigger(module: _TriggerModule, options: Sequence[dict[str, int]], *, start_state: Any,
                    expected: Any, nothing_plausible: bool, result: Extraction) -> _TriggerAnswer:
    """The candidate frame kept for one trigger: the first whose answer is within θ, else the closest.

    Each candidate after the first starts from ``start_state`` (None: only
    one candidate). The kept answer's ``state`` is None when the planner
    already holds the state after it. Adds the step and comparison times
    to ``result``.
    """
    planner, cfg = module.planner, module.cfg
    best: _TriggerAnswer | None = None
    for tries, choice in enumerate(options, start=1):
        frame = {name: module.usable[name][i][1] for name, i in choice.items()}
        if tries > 1 and start_state is not None:
            planner.restore(copy.deepcopy(start_state))
        t2 = time.perf_counter()
        error = None
        try:
            replayed = within_limit(functools.partial(planner.step, frame), cfg.hang_after)
        except StepHang as exc:
            replayed, error = None, f"the module hangs: {exc}"
        except Exception as exc:  # the module under test may crash on a frame: that is data
            replayed, error = None, f"{type(exc).__name__}: {exc}"
        t3 = time.perf_counter()
        result.planner_seconds += t3 - t2
        if error is not None:
            cmp = Comparison(math.inf, math.inf, 0, "error")
        elif replayed is None:
            cmp = Comparison(0.0, 0.0, 0, "both empty") if nothing_plausible else Comparison(
                math.inf, math.inf, 0, "one empty")
        else:
            cmp = compare_outputs(cfg, replayed, expected)
        result.validation_seconds += time.perf_counter() - t3
        if error is None and cmp.within(cfg.threshold):
            return _TriggerAnswer(cmp, choice, replayed, error, None, tries)
        if best is None or cmp.distance < best.comparison.distance:
            state = planner.snapshot() if start_state is not None else None
            best = _TriggerAnswer(cmp, choice, replayed, error, state, tries)
    assert best is not None
    return best


def _answered_in_turn(times: Sequence[int], t_index: int, outputs: list[LoggedMessage], next_output: int) -> bool:
    """Is the trigger at ``t_index`` answered by the next of the outputs not paired yet?

    A module answers its triggers in order. The outputs logged within one
    trigger period answer the last triggers before them, as many as there
    are: one, normally; several when the module worked off a backlog (seen
    under load: control answered three queued localizations at once when its
    first trajectory came). A trigger before those got no answer.
    """
    first = outputs[next_output].log_time
    newest = bisect_right(times, first) - 1  # the newest trigger at or before the first pending output
    if newest <= t_index:
        return True
    end = times[newest + 1] if newest + 1 < len(times) else math.inf
    burst = bisect_left([o.log_time for o in outputs[next_output:next_output + newest - t_index + 1]], end)
    return t_index > newest - burst


def log_start(log: LogContents) -> int:
    return min((m.log_time for key in log.channels for m in log.on(key)), default=0)


def _recorded_cycle_s(outputs: list[LoggedMessage], index: int) -> float:
    """The time the recorded planner took for this output: the gap since its previous one (or the median)."""
    gaps = sorted(b.log_time - a.log_time for a, b in pairwise(outputs))
    median = gaps[len(gaps) // 2] * 1e-9 if gaps else 0.0
    if index == 0:
        return median
    return max(median, (outputs[index].log_time - outputs[index - 1].log_time) * 1e-9)


@dataclass
class _Recorded:
    """The replayed module's recorded traffic: its inputs (decoded on demand, once) and outputs, in log order."""

    messages: dict[str, list[LoggedMessage]]  # input channel → its messages
    outputs: list[LoggedMessage]
    streams: dict[str, Stream]
    codecs: dict[str, Codec]
    index_of: dict[str, dict[int, int]]  # input channel → id(message) → its index in ``messages``
    decoded: dict[tuple[str, int], Any] = field(default_factory=dict)
    module_started_in_log: bool = False  # the run's start is logged before the module's first trigger

    @classmethod
    def read(cls, log: LogContents, spec: Spec, cfg: ReplayModule) -> _Recorded:
        """Raises InputError when the log lacks one of the module's channels."""
        messages = channel_messages(log, spec, list(cfg.inputs) + [cfg.output])
        outputs = messages.pop(cfg.output)
        started = [r.time_ns for r in log.records(rec.RunStarted)]
        triggers = messages[cfg.trigger]
        return cls(messages=messages, outputs=outputs,
                   module_started_in_log=bool(started and triggers and started[0] <= triggers[0].log_time),
                   streams={name: Stream(name, [m.log_time for m in msgs]) for name, msgs in messages.items()},
                   codecs={name: get_codec(spec.channel(name).encoding) for name in list(cfg.inputs) + [cfg.output]},
                   index_of={name: {id(msg): i for i, msg in enumerate(msgs)} for name, msgs in messages.items()})

    def declared(self, cfg: ReplayModule, output_message: Any, previous: Mapping[str, int], until: int
                 ) -> Candidate | None:
        """The frame the output says it used (``cfg.provenance``: {input: its header.seq or header.stamp}; an
        input it names with null, or not at all, was absent), or None when the output names none we have."""
        named = provenance_of(output_message, cfg.provenance)
        if named is None:
            return None
        choice: dict[str, int] = {}
        for name in cfg.inputs:
            if named.get(name) is None:
                if name == cfg.trigger:
                    return None
                continue
            times = self.streams[name].times
            newest = bisect_right(times, until) - 1
            found = next((i for i in range(newest, previous.get(name, 0) - 1, -1)
                          if names_message(self.decode(name, i), named[name])), None)
            if found is None:
                return None
            choice[name] = found
        return Candidate(self.streams[cfg.trigger].times[choice[cfg.trigger]], choice,
                         frozenset({(DECLARED, ())}))

    def fresh(self, name: str, idx: int) -> Any:
        """Message ``idx`` of input ``name`` decoded anew (None if it does not decode): what a module steps on
        gets its own objects, as in the suite's run (a module may change its inputs in place)."""
        if self.decode(name, idx) is None:
            return None
        return self.codecs[name].decode(self.messages[name][idx].data)

    def decode(self, name: str, idx: int) -> Any:
        """Message ``idx`` of input ``name`` decoded, or None if it does not decode."""
        k = (name, idx)
        if k not in self.decoded:
            try:
                self.decoded[k] = self.codecs[name].decode(self.messages[name][idx].data)
            except DecodeError:
                self.decoded[k] = None
        return self.decoded[k]


@dataclass(frozen=True)
class _Expected:
    """A recorded output as every candidate's replayed output is judged against it (computed once per output)."""

    message: Any  # decoded; None if it does not decode
    points: list[Any]  # its trajectory's points (a planner with a trajectory layout), else []
    text: str  # its text form (see _text)


@dataclass(frozen=True)
class _Judged:
    """The kept candidate's judgement: its comparison, whether it reproduced the output field for field,
    the candidates tried for it (all of them when none was within θ)."""

    comparison: Comparison
    exact: bool
    tries: int


@dataclass
class _Run:
    """The state the steps of one extraction (:func:`_extract`) share, in the process that carries it on."""

    planner: ReplayPlanner
    cfg: ReplayModule
    recorded: _Recorded
    search: ForkedSearch | None  # None: candidates stepped here from deep copies of the state
    progress: OnOutput
    result: Extraction
    previous: dict[str, int] = field(default_factory=dict)  # the choice kept for the output before
    memory: SearchMemory = field(default_factory=SearchMemory)  # how earlier kept frames were derived, their time
    speculation: Speculation = field(default_factory=lambda: Speculation())
    last_step_s: float | None = None  # the CPU time of the last accepted step: a cycle's measured cost
    misses_in_row: int = 0  # outputs kept just before this one that no candidate reproduced (forked search)
    # The suite's own run done by the replay (see SuiteRun): ``born`` is the process that made ``planner``
    # fresh and stepped it on every frame kept, in order (None: no such process — the caller runs the suite).
    born: int | None = None

    def report(self, out_index: int, skipped: str | None = None, silent: int = 0) -> None:
        """Pass on the output just decided (its frame is the last one, after ``silent`` frames of cycles that
        published nothing; ``skipped``: none, and why).

        A shadow following the runner reports nothing: the runner does.
        """
        if skipped is not None:
            self.result.skipped.append((out_index, skipped))
        frame = self.result.frames[-1] if skipped is None else None
        before = tuple(self.result.frames[-1 - silent:-1]) if silent and frame is not None else ()
        if self.speculation.following is None:
            index_of = self.recorded.index_of
            in_order = self.in_order(len(before) + 1) if frame is not None else None
            self.progress(out_index + 1, len(self.recorded.outputs), Decided(
                out_index, frame, None if frame is None else {
                    name: index_of[name][id(msg)] for name, msg in frame.inputs.items()}, skipped, before,
                in_order, self.born is None))

    def keep(self, out_index: int, cand: Candidate, judged: _Judged) -> None:
        """Record ``cand`` as the frame of output ``out_index`` and report it."""
        self.previous = dict(cand.choice)
        recorded, cfg = self.recorded, self.cfg
        for silent in cand.silent:  # cycles that published nothing, stepped first: in the suite for their state
            self.result.frames.append(ExtractedFrame(
                index=len(self.result.frames), output=None,
                trigger_time=recorded.streams[cfg.trigger].times[silent[cfg.trigger]],
                frame_time=recorded.streams[cfg.trigger].times[silent[cfg.trigger]],
                inputs={name: recorded.messages[name][idx] for name, idx in silent.items()},
                comparison=Comparison(0.0, 0.0, 0, "silent"), accepted=False, candidates_tried=0, exact=False))
        self.result.frames.append(ExtractedFrame(
            index=len(self.result.frames), output=recorded.outputs[out_index],
            trigger_time=recorded.streams[cfg.trigger].times[cand.choice[cfg.trigger]], frame_time=cand.frame_time,
            inputs={name: recorded.messages[name][idx] for name, idx in cand.choice.items()},
            comparison=judged.comparison, accepted=judged.comparison.within(cfg.threshold),
            candidates_tried=judged.tries, exact=judged.exact))
        self.report(out_index, silent=len(cand.silent))

    def in_order(self, new: int) -> tuple[InOrder, ...] | None:
        """The suite's run of the ``new`` frames just kept, if this process did it (see Decided.in_order).

        In the process that made the module, stepping every frame kept in order, they were judged as the
        suite judges them. Once a fork took over (the kept frame was not the first candidate this process
        stepped), its module is a copy, not one made where it runs (a module may answer otherwise in a forked
        process), and the caller steps the suite beside from then on: stepping every frame again here on a
        fresh module would lengthen the search by as many steps (measured on the zoo: 10-45 % of the
        extraction's time), while the caller's run uses a core the search mostly leaves idle.
        """
        if self.born is not None and self.born != os.getpid():
            self.born = None
        if self.born is None:
            return None
        return tuple((f.index, f.comparison if f.output is not None else None, f.exact)
                     for f in self.result.frames[-new:])


def _extract(log: LogContents, spec: Spec, planner: ReplayPlanner, progress: OnOutput, *,
             search: ForkedSearch | None, cfg: ReplayModule, resume: Sequence[Decided] = (),
             made_here: bool = False) -> Extraction:
    """A frame per recorded output, in order (see :func:`extract`); ``search`` None: no forking.

    In a forked search, the process that returns is the one holding the
    state after the last output kept; a shadow that was told to keep the
    last output exits here instead (the runner reports). ``made_here``:
    ``planner`` was made fresh in this process (its in-order steps are the
    suite's own run until a fork takes over).
    """
    recorded = _Recorded.read(log, spec, cfg)
    run = _Run(planner, cfg, recorded, search, progress, Extraction(outputs=len(recorded.outputs)),
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


def _extract_output(run: _Run, out_index: int, before: Decided | None) -> None:
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
    options, capped = run.memory.order(generic, expensive=expensive, first=not run.previous and planner.can_snapshot,
                                       trigger=cfg.trigger)
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
    _decide_forked(run, out_index, options, expected, capped=capped, window=window, expensive=expensive)


def _generic_candidates(run: _Run, out_index: int) -> list[Candidate]:
    """The output's candidate frames from the log alone, most likely first (:func:`.frames.candidates`)."""
    cfg, recorded = run.cfg, run.recorded
    outputs, skew = recorded.outputs, int(cfg.skew_ms * 1e6)
    output = outputs[out_index]
    # A plain replay's frame (everything logged by the output), the cycle's start (the output's time minus the
    # step's measured cost), the previous output's time (a busy module starts a cycle as it ends one).
    read_at = read_times(recorded.streams, cfg.trigger, run.previous, output_ns=output.log_time,
                         previous_output_ns=outputs[out_index - 1].log_time if out_index else None,
                         step_ns=None if run.last_step_s is None else int(run.last_step_s * 1e9))
    return candidates(OutputContext(
        streams=recorded.streams, trigger=cfg.trigger, output_ns=output.log_time + skew, previous=run.previous,
        lookback_ns=int(cfg.lookback_ms * 1e6),
        previous_output_ns=outputs[out_index - 1].log_time + skew if out_index else None, read_at=read_at,
        module_started_in_log=recorded.module_started_in_log, skew_ns=skew,
        earlier_outputs_ns=[o.log_time for o in reversed(outputs[max(0, out_index - 4):out_index - 1])]))


def _put_first(run: _Run, out_index: int, options: list[Candidate], expected: _Expected, *,
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
        again = Candidate(outputs[out_index - 1].log_time, dict(run.previous), frozenset({(AGAIN, ())}))
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


def _decide_forked(run: _Run, out_index: int, options: list[Candidate], expected: _Expected, *, capped: bool,
                   window: float, expensive: bool) -> None:
    """Search the options in forked copies with their time limits; keep the best and learn from it."""
    cfg, result, outputs = run.cfg, run.result, run.recorded.outputs
    output, skew = outputs[out_index], int(cfg.skew_ms * 1e6)
    full_limit = candidate_limit(_recorded_cycle_s(outputs, out_index))
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


def _measure_copies(run: _Run, cand: Candidate, limit_s: float) -> None:
    """Step two copies of the module's state on one frame (forked copies, or deep copies where the search
    made those) and record how far apart their answers are: whether the state survives copying is then
    measured, not guessed. The state carried on is untouched (forks), or a deep copy (as in that search)."""
    if run.speculation.following is not None or not run.planner.can_snapshot:
        return  # a shadow leaves it to the runner; a process replay cannot copy its module
    frame = {name: run.recorded.decode(name, idx) for name, idx in cand.choice.items()}
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
    reference = _Expected(first, trajectory_points(first, cfg.trajectory) if cfg.trajectory is not None else [],
                          _text(first))
    cmp, exact = _judged(cfg, second, reference)
    run.result.copies_differ = 0.0 if exact else cmp.distance


def _step_resumed(run: _Run, out_index: int, before: Decided, *, generic: Sequence[Candidate], window: float
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
    comparison, exact = _judged(run.cfg, replayed, _expected(run, out_index))
    stepped = replace(stepped, comparison=comparison, exact=exact, accepted=comparison.within(run.cfg.threshold))
    run.result.frames.append(replace(stepped, index=len(run.result.frames)))
    for cand in generic if before.frame.accepted else ():
        if dict(cand.choice) == run.previous:
            run.memory.learn(cand, step_s, window,
                             expensive=run.search is not None and window > SPECULATE_MAX_WINDOW_S)
    run.report(out_index)


DECLARED = "declared"  # a frame the module's own output names (provenance)
AGAIN = "again"  # the previous output's frame again: the next message of one cycle


def provenance_of(message: object, path: str | None) -> Mapping[str, object] | None:
    """The inputs an output names as used (``path``: the spec's ``provenance``), or None."""
    from astaa_deft.model.fields import get

    if path is None or message is None:
        return None
    found = get(message, path)
    return found[0][1] if found and isinstance(found[0][1], Mapping) else None


def names_message(message: object, named: object) -> bool:
    """Is ``message`` the one an output names by ``named`` (its header.seq, or its header.stamp)?"""
    header = message.get("header") if isinstance(message, Mapping) else None
    if not isinstance(header, Mapping):
        return False
    if isinstance(named, bool):
        return False
    if isinstance(named, int) and header.get("seq") == named:
        return True
    return header.get("stamp") == named


def _expected(run: _Run, out_index: int) -> _Expected:
    """Recorded output ``out_index`` decoded (a warning in the result when it does not decode)."""
    cfg = run.cfg
    try:
        message = run.recorded.codecs[cfg.output].decode(run.recorded.outputs[out_index].data)
    except DecodeError as exc:
        message = None
        run.result.warnings.append(f"output {out_index}: recorded output does not decode ({exc})")
    points = trajectory_points(message, cfg.trajectory) if cfg.trajectory is not None else []
    return _Expected(message, points, _text(message))


def _search_in_process(run: _Run, options: Sequence[Candidate], expected: _Expected
                       ) -> tuple[Candidate, _Judged] | None:
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
        frame = {name: run.recorded.decode(name, idx) for name, idx in cand.choice.items()}
        result.reconstruction_seconds += time.perf_counter() - t0
        if any(v is None for v in frame.values()):
            continue
        t1 = time.perf_counter()
        if tries > 1 and start_state is not None:
            planner.restore(copy.deepcopy(start_state))
        try:
            replayed = planner.step(frame)
        except Exception as exc:  # the planner under test may crash on a frame: that is data
            replayed = {"__replay_error__": f"{type(exc).__name__}: {exc}"}
        t2 = time.perf_counter()
        result.planner_seconds += t2 - t1
        step_s = t2 - t1
        cmp, exact = _judged(cfg, replayed, expected)
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
    return cand, _Judged(cmp, exact, tries)


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


# One candidate stepped: (its comparison, equal to the recorded output field for field, its step's CPU seconds).
_Outcome = tuple[Comparison, bool, float, tuple[dict[str, int], ...] | None]  # … for a plain walk: its frames

# A cheap output's candidates are stepped in the runner itself, one after another, a shadow copy following
# one output behind (see fork_replay.shadow), when the recorded planner answered within this window: a cheap
# cycle, whose wrong frames are cheap too (a wrong frame stepped in the runner cannot be cut). Forking a worker
# per candidate costs as much as such a step (docs/performance.md, "analysis").
SPECULATE_MAX_WINDOW_S = 0.05
# The runner's word to its shadow on an output: (KEEP, i): candidate i is kept, step it and follow on;
# (TRY_ON, outcomes so far by candidate): carry on as the runner from the state before the output, trying
# the candidates not tried yet. Each word also carries the runner's counters.
KEEP, TRY_ON = "keep", "try on"
DEEP_MISSES = 4  # outputs in a row not reproduced after which only the likeliest candidate is stepped
NARROWING = 2  # … before that, each output not reproduced divides the candidates tried by 2 ** NARROWING
IN_TURN = 2  # a cheap output's candidates stepped in turn at most (then a forked search, with time limits)


@dataclass
class Speculation:
    """The runner's shadow (a copy one output behind, see fork_replay.shadow), or in a shadow what it follows."""

    shadow: Shadow | None = None  # in the runner
    following: Following | None = None  # in a shadow: where the runner's word comes from
    # The last output kept was reproduced field for field: then a candidate that reproduces only the
    # trajectory (a standing ego: the same points from another pose message, another stamp) does not end
    # the search, the others are searched for the exact one (none: the closest is kept as before). A stack
    # whose outputs never match exactly is not held up: after one such output this is off again.
    expect_exact: bool = False
    hits: int = 0  # cheap outputs whose first candidate was accepted
    misses: int = 0  # … was not: the shadow took over and tried the others

    def shadow_here(self) -> None:
        """Fork a shadow unless one follows already (in the new shadow this returns with ``following`` set)."""
        if self.shadow is None and self.following is None:
            handle = shadow()
            if isinstance(handle, Following):
                self.following = handle
            else:
                self.shadow = handle

    def word(self) -> tuple[str, Any]:
        """In a shadow: the runner's word on the output at hand (it exits when the runner has none)."""
        assert self.following is not None
        kind, argument, (self.hits, self.misses) = next_word(self.following)
        if kind != KEEP:  # from here on this process is the runner
            os.close(self.following.word_fd)
            self.following = None
        return kind, argument

    def tell(self, kind: str, argument: Any) -> None:
        """In the runner: its word to the shadow; with any word but KEEP the runner ends here."""
        if self.shadow is None:
            assert kind == KEEP, "only a runner with a shadow hands an output over"
            return
        word = (kind, argument, (self.hits, self.misses))
        if kind == KEEP:
            tell(self.shadow, word)
        else:
            hand_over(self.shadow, word)

    def let_go(self) -> None:
        if self.shadow is not None:
            drop(self.shadow)
            self.shadow = None


def _step_in_turn(count: int, run: Callable[[int], Any], accepted: Callable[[Any], bool], speculation: Speculation,
                  *, in_turn: bool) -> tuple[tuple[int, Any] | None, dict[int, Any]]:
    """(candidate and outcome kept, or None; candidates tried in vain) for one output, stepped in this process.

    ``in_turn`` (a cheap output with several candidates): the first
    ``IN_TURN`` candidates are stepped here in order, a shadow holding the
    state from before the output; the first accepted is kept and the shadow
    steps it too; a wrong one hands the output over to the shadow, which
    tries the next (with a shadow of its own). A lone candidate is stepped
    here (the shadow, if any, follows). Anything else (None) is left to the
    forked search, whose time limits stop a wrong frame that searches long.
    """
    tried: dict[int, Any] = {}  # outcomes of the candidates tried so far on this output
    while True:
        if in_turn:
            speculation.shadow_here()  # (in the new shadow this returns too: it waits for the word on this output)
        if speculation.following is not None:
            kind, argument = speculation.word()
            if kind == TRY_ON:  # a candidate was wrong: this process, in the state from before, tries the next
                tried = argument
                if len(tried) >= IN_TURN:
                    return None, dict(tried)
                continue
            return (argument, run(argument)), {}
        if count == 1:
            outcome = run(0)
            if outcome is None:
                return None, {}
            speculation.tell(KEEP, 0)
            return (0, outcome), {}
        if not in_turn:
            return None, {}
        index = len(tried)  # in turn: the candidates in order
        outcome = run(index)
        if accepted(outcome):
            speculation.hits += index == 0
            speculation.tell(KEEP, index)
            return (index, outcome), {}
        speculation.misses += index == 0
        tried[index] = outcome
        speculation.tell(TRY_ON, tried)  # does not return: the shadow carries on from the state before


DONE = "done"  # the runner's word to an output's checkpoint copy: its first candidate was kept, exit
DIED = "died"  # what a checkpoint copy reads when its runner died on the first candidate (cut, or crashed)


def _step_first_here(run: Callable[[int], Any], accepted: Callable[[Any], bool], speculation: Speculation,
                     limit_s: float) -> tuple[tuple[int, Any] | None, dict[int, Any]]:
    """(candidate and outcome kept, or None; candidates tried in vain) of an expensive output: its first
    candidate stepped right here, as a plain replay would — no fork to wait for — a checkpoint copy forked
    just before holding the state from before the output.

    Right (the usual case: the learned way first), the copy is told to exit.
    Wrong, the output goes over to the copy, which searches the others
    (forked, with their time limits) and this process ends. The step may
    use ``limit_s`` of CPU time: past it this process is killed (native code
    too) and the copy takes over as from a wrong candidate, retrying it
    last under the full limit if nothing else is accepted.
    """
    if speculation.following is not None:  # a shadow of cheap outputs: the runner drops it here, it exits
        speculation.word()
    speculation.let_go()  # a shadow following cheap outputs is not this output's checkpoint
    handle = shadow()
    if isinstance(handle, Following):  # the checkpoint copy, at the state from before the output
        word = next_word(handle, at_end=(DIED, None, (speculation.hits, speculation.misses)))
        os.close(handle.word_fd)
        kind, argument, (speculation.hits, speculation.misses) = word
        if kind == DONE:
            os._exit(0)
        # Tried in vain (its outcome), or cut (None): the others first, then it again under the search's limits.
        return None, {0: argument[0] if kind == TRY_ON else None}
    with cpu_limit(limit_s):
        outcome = run(0)
    counters = (speculation.hits, speculation.misses)
    if accepted(outcome):
        tell(handle, (DONE, None, counters))
        drop(handle)
        return (0, outcome), {}
    hand_over(handle, (TRY_ON, {0: outcome}, counters))  # does not return: the copy carries on
    raise AssertionError("unreachable")


def _walk(run: _Run, start: Candidate, expected: _Expected, until_ns: int) -> _Outcome:
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
        frame = {name: recorded.fresh(name, idx) for name, idx in choice.items()}
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
    return (*_judged(cfg, replayed, expected), step_s, tuple(walked))


def _search_forked(run: _Run, options: Sequence[Candidate], expected: _Expected, *, limit_s: float,
                   full_limit_s: float, cheap: bool, until_ns: int = 0) -> tuple[Candidate, _Judged, float] | None:
    """(candidate, its judgement, its step's CPU seconds) kept for one output, in the process that carries
    on; or None. Candidates cut by ``limit_s`` run again under ``full_limit_s`` if no other is accepted.
    A ``cheap`` output's candidates are stepped right here, one after another (see :func:`_step_in_turn`)."""
    planner, cfg, result, speculation = run.planner, run.cfg, run.result, run.speculation
    assert run.search is not None
    search = run.search
    t0 = time.perf_counter()
    decodes = [all(run.recorded.decode(name, idx) is not None for name, idx in cand.choice.items())
               for cand in options]
    result.reconstruction_seconds += time.perf_counter() - t0

    def run_candidate(index: int) -> _Outcome | None:
        if options[index].walk:
            return _walk(run, options[index], expected, until_ns)
        if not decodes[index]:
            return None
        frame = {name: run.recorded.fresh(name, idx) for name, idx in options[index].choice.items()}
        if any(v is None for v in frame.values()):
            return None
        started = time.process_time()  # CPU time, as the limits count it: the load does not count
        try:
            replayed = planner.step(frame)
        except Exception as exc:  # the planner under test may crash on a frame: that is data
            replayed = {"__replay_error__": f"{type(exc).__name__}: {exc}"}
        step_s = time.process_time() - started
        return (*_judged(cfg, replayed, expected), step_s, None)

    def accepted(outcome: _Outcome | None) -> bool:
        """Within θ; and field for field while the outputs before were (else the closest is kept)."""
        return outcome is not None and outcome[0].within(cfg.threshold) and (
            outcome[1] or not speculation.expect_exact)

    def settles(outcome: _Outcome) -> bool:
        """No other candidate can do better: the output reproduced field for field, or (outputs not expected
        field for field) within floating-point noise of it — the right frame on a planner not bit-stable."""
        cmp, exact = outcome[0], outcome[1]
        return (exact and cmp.within(cfg.threshold)) or (
            not speculation.expect_exact and 0.0 < cmp.distance <= NEAR_MISS_M)

    t1 = time.perf_counter()
    if cheap or len(options) == 1:
        kept, in_vain = _step_in_turn(len(options), run_candidate,
                                      lambda outcome: accepted(outcome) or (outcome is not None and settles(outcome)),
                                      speculation, in_turn=cheap and len(options) > 1)
    else:
        kept, in_vain = _step_first_here(
            run_candidate, lambda outcome: accepted(outcome) or (outcome is not None and settles(outcome)),
            speculation, limit_s)
    # The forked search tries those not tried in turn first (they were wrong, but may be the closest).
    others = [i for i in range(len(options)) if i not in in_vain]
    known = all(outcome is not None for outcome in in_vain.values())
    rounds = [others, sorted(in_vain)] if known and in_vain and others else [others + sorted(in_vain)]
    # Those tried in vain are stepped again only if none of the others comes as close (their outcome is known;
    # the kept candidate's state is needed): a module that has left the recorded state costs a step less.
    rival = min((outcome[0].distance for outcome in in_vain.values()), default=math.inf) if len(rounds) > 1 \
        else math.inf
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
    if kept is None or kept[1] is None:
        return None
    index, (cmp, exact, step_s, walked) = kept
    speculation.expect_exact = exact
    tries = index + 1 if cmp.within(cfg.threshold) or 0.0 < cmp.distance <= NEAR_MISS_M else len(options)
    cand = options[index]
    if walked:  # the plain walk: the frames it stepped, the last answering
        cand = Candidate(run.recorded.streams[cfg.trigger].times[walked[-1][cfg.trigger]], walked[-1],
                         cand.patterns, tuple(walked[:-1]))
    return cand, _Judged(cmp, exact, tries), step_s


def _forked_near(outcome: _Outcome) -> bool:
    """A forked candidate within floating-point noise of the output settles its search even while outputs
    reproduce field for field: they do in the replay process that made the module (its own steps), a forked copy
    of a module not bit-stable across a fork never can; the suite's own run judges it on a fresh module."""
    return 0.0 < outcome[0].distance <= NEAR_MISS_M


def _nth(order: Sequence[int], run: Callable[[int], Any], k: int) -> Any:
    """``run`` on the ``k``-th candidate of ``order``."""
    return run(order[k])


def _judge(cfg: ReplayModule, replayed: Any, expected: Any, expected_points: list[Any]) -> Comparison:
    """The planner's trajectories (points decoded once per output), or any module's output field by field."""
    if cfg.trajectory is not None:
        return compare(trajectory_points(replayed, cfg.trajectory), expected_points)
    return compare_outputs(cfg, replayed, expected)


def _judged(cfg: ReplayModule, replayed: Any, expected: _Expected) -> tuple[Comparison, bool]:
    """(comparison, equal to the recorded output field for field) of one replayed output.

    Most replayed outputs equal the recording: then the trajectories are
    the same points, and their comparison is known without measuring
    (``validator.identical``; why: docs/performance.md, "analysis").
    """
    exact = _text(replayed) == expected.text
    if exact and cfg.trajectory is not None:
        return identical(expected.points), True
    return _judge(cfg, replayed, expected.message, expected.points), exact


def search_note(extraction: Extraction) -> str | None:
    """What the candidate search did to save time, when it did anything: for the extraction summary."""
    parts = []
    if extraction.reordered:
        parts.append(f"{extraction.reordered} output(s) tried first the way earlier outputs were reproduced "
                     f"(trigger rule and input offsets)")
    stepped = extraction.first_stepped_in_runner + extraction.first_missed_in_runner
    if stepped:
        parts.append(f"{stepped} cheap output(s) stepped their first candidate in the replay process "
                     f"({extraction.first_missed_in_runner} wrong: searched on by a copy one output behind)")
    if extraction.capped:
        parts.append(f"{extraction.capped} output(s) not reproduced by their likeliest candidates (at most "
                     f"{EXPENSIVE_TRIES} for an expensive output; after outputs in a row not reproduced, 8, 2, "
                     f"then 1: the module's state has left the recorded one), the others not tried")
    if extraction.candidates_cut:
        parts.append(f"{extraction.candidates_cut} candidate(s) cut by the time limit learned from the accepted "
                     f"steps, {extraction.cut_retried} of them retried under the full limit (nothing else was "
                     f"accepted), {extraction.retried_kept} kept after that")
    if extraction.declared:
        parts.append(f"{extraction.declared} output(s) named the inputs they used (provenance): that frame tried "
                     f"first")
    if extraction.checked_in_replay:
        parts.append(f"the suite's own run done by the replay's in-order steps of a fresh module for "
                     f"{extraction.checked_in_replay} frame(s)")
    elif extraction.checked_beside:
        parts.append(f"the suite's own run stepped {extraction.checked_beside} frame(s) beside the search")
    if extraction.confirmed_unforked:
        parts.append(f"{extraction.confirmed_unforked} output(s) reproduced by the suite's own run (a fresh module, "
                     f"not forked) though forked copies answered a little off")
    return "candidate search: " + "; ".join(parts) if parts else None


NEAR_MISS_M = 1e-9


def near_miss_note(extraction: Extraction, unit: str = " m") -> str | None:
    """Why outputs that match at 1e-9 m are not counted at θ = 0: the distances, what was measured about their
    cause, and the flag that sets θ (``unit``: "" for a module compared field by field)."""
    near = sorted(f.comparison.distance for f in extraction.frames if 0.0 < f.comparison.distance <= NEAR_MISS_M)
    if not near:
        return None
    quantiles = ", ".join(f"{name} {near[min(len(near) - 1, int(q * len(near)))]:.3g}{unit}"
                          for name, q in (("min", 0.0), ("median", 0.5), ("p90", 0.9)))
    measured = extraction.copies_differ
    if measured is None:
        why = "floating-point noise (not measured whether copies of the module's state answer alike)"
    elif measured == 0.0:
        why = ("not the copying: two copies of the module's state stepped on the same frame answer bit for bit "
               "(measured), so the frame or the module's own run-to-run noise differs")
    else:
        why = (f"the module's state does not survive copying bit for bit: two copies stepped on the same frame "
               f"answer {measured:.3g}{unit} apart (measured)")
    return (f"{len(near)} output(s) match within {NEAR_MISS_M:g}{unit} but not exactly (distances: {quantiles}, "
            f"max {near[-1]:.3g}{unit}): {why}. If that is acceptable, set θ with --threshold {NEAR_MISS_M:g} "
            f"(or the module's threshold in the spec).")


def _text(value: Any) -> str:
    """A decoded message as text that is equal exactly when the messages are equal field for field."""
    return json.dumps(value, sort_keys=True, default=str)


def _same(a: Any, b: Any) -> bool:
    return _text(a) == _text(b)


def ground_truth_rate(extraction: Extraction, spec: Spec, debug_path: str = "debug.inputs",
                      entry: ReplayModule | None = None) -> tuple[int, int]:
    """(frames whose chosen inputs are those the module's output names, frames checked).

    Evaluation only: reads the output's record (``debug_path``, e.g. the demo
    planner's debug block) naming the header sequence numbers (or stamps) of
    the inputs it used; an input named null was absent. ``entry``: the module
    (default: the planner).
    """
    cfg = entry if entry is not None else planner_of(spec)
    codec = get_codec(spec.channel(cfg.output).encoding)
    exact = checked = 0
    for f in extraction.frames:
        if f.output is None:
            continue
        try:
            truth = provenance_of(codec.decode(f.output.data), debug_path)
        except DecodeError:
            continue
        if truth is None:
            continue
        checked += 1
        same = True
        for name, named in truth.items():
            msg = f.inputs.get(name)
            if msg is None:
                same = same and named is None
                continue
            try:
                same = same and names_message(get_codec(spec.channel(name).encoding).decode(msg.data), named)
            except DecodeError:
                same = False
        exact += same
    return exact, checked
