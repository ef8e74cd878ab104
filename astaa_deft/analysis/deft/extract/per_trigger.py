"""Per-trigger modules: one frame per trigger message, each answer paired with the recorded outputs in order."""

from __future__ import annotations

import contextlib
import copy
import functools
import math
import time
from bisect import bisect_left, bisect_right
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from astaa_deft.analysis.deft.extract.judging import same_fields
from astaa_deft.analysis.deft.extract.recorded import channel_messages, log_start
from astaa_deft.analysis.deft.extract.records import Decided, ExtractedFrame, Extraction, OnOutput
from astaa_deft.analysis.deft.frames import Stream, trigger_candidates
from astaa_deft.analysis.deft.replay import ReplayPlanner, StepHang, compare_outputs, within_limit
from astaa_deft.analysis.deft.validator import Comparison
from astaa_deft.engine.spec.replay_section import ReplayModule
from astaa_deft.io.codecs import get_codec
from astaa_deft.io.codecs.base import Codec, DecodeError
from astaa_deft.io.log.reader import LogContents, LoggedMessage
from astaa_deft.model.sut import Spec


@dataclass(frozen=True)
class _TriggerModule:
    """What every frame of a per-trigger replay reads: the module, its settings, the decodable inputs."""

    planner: ReplayPlanner
    cfg: ReplayModule
    usable: Mapping[str, list[tuple[LoggedMessage, Any]]]  # channel → (message, decoded), log order


@dataclass(frozen=True, kw_only=True)
class _TriggerAnswer:
    """One candidate frame of a trigger as stepped (in the end: the one kept)."""

    comparison: Comparison
    choice: dict[str, int]
    replayed: Any  # the module's answer; None: it answered nothing (or failed)
    error: str | None  # the module crashed or hung on this frame
    state: Any  # the planner state after this frame, or None: the planner's current state
    tries: int


def extract_per_trigger(log: LogContents, spec: Spec, planner: ReplayPlanner, *, cfg: ReplayModule,
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
        nothing_plausible = output is None or t_index + 1 >= len(times) or not answered_in_turn(
            times, t_index, outputs, next_output, skew_ns=int(cfg.skew_ms * 1e6))
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
            exact=kept.error is None and same_fields(kept.replayed, expected if answered else None)))
        progress(done, len(triggers), Decided(output_index=done - 1, frame=result.frames[-1], choice=kept.choice))
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
            cmp = Comparison(distance=math.inf, max_error=math.inf, points=0, how="error")
        elif replayed is None:
            cmp = Comparison(distance=0.0, max_error=0.0, points=0,
                             how="both empty") if nothing_plausible else Comparison(
                distance=math.inf, max_error=math.inf, points=0, how="one empty")
        else:
            cmp = compare_outputs(cfg, replayed, expected)
        result.validation_seconds += time.perf_counter() - t3
        if error is None and cmp.within(cfg.threshold):
            return _TriggerAnswer(comparison=cmp, choice=choice, replayed=replayed, error=error, state=None,
                                  tries=tries)
        if best is None or cmp.distance < best.comparison.distance:
            state = planner.snapshot() if start_state is not None else None
            best = _TriggerAnswer(comparison=cmp, choice=choice, replayed=replayed, error=error, state=state,
                                  tries=tries)
    assert best is not None
    return best


def answered_in_turn(times: Sequence[int], t_index: int, outputs: list[LoggedMessage], next_output: int, *,
                     skew_ns: int = 0) -> bool:
    """Is the trigger at ``t_index`` answered by the next of the outputs not paired yet?

    A module answers its triggers in order. The outputs logged within one
    trigger period answer the last triggers before them, as many as there
    are: one, normally; several when the module worked off a backlog (seen
    under load: control answered three queued localizations at once when its
    first trajectory came). A trigger before those got no answer.

    A trigger logged up to ``skew_ns`` after the output may have reached the
    module before it: the recorder and the module each see their own arrival
    order (seen under load: control's first command logged 0.04 ms before the
    localization it answered). Such a trigger counts as one before the output,
    so the trigger before it may have got no answer: the frame as plainly
    replayed (the module, still without a trajectory, answering nothing) is
    then within reach, and is tried first, as for any frame.
    """
    first = outputs[next_output].log_time
    newest = bisect_right(times, first + skew_ns) - 1  # the newest trigger that may have come before it
    if newest <= t_index:
        return True
    end = times[newest + 1] if newest + 1 < len(times) else math.inf
    burst = bisect_left([o.log_time for o in outputs[next_output:next_output + newest - t_index + 1]], end)
    return t_index > newest - burst
