"""The plain-replay floor: the logged inputs, in their logged order, into one fresh instance of the step.

What a user gets without DeFT's search, and so the least extraction must
reproduce. The log is played in arrival order (the recorder's log time),
each input's newest message kept (an input not logged yet is absent from
the frame, as the factory contract says), into one fresh instance of the
member's factory, carrying its state. When to step is the one thing a
plain replay must assume; there are three plain ways, each tried with its
own fresh instance, and the floor is the best of them:

* ``at_trigger`` — at every trigger message, with the inputs as they stood
  when it arrived (a module that answers each trigger, rosbag-style); its
  answers (not None) pair in order with the recorded outputs. Tried for a
  ``per_output`` module only when the log holds at most 1.5 triggers per
  output (one answering nearly every trigger): stepping every trigger of a
  module that skips most is no plain replay of it;
* ``at_output`` (``per_output`` modules) — once per recorded output, with
  the inputs as they stood when the output was logged;
* ``output_trigger`` (``per_output`` modules) — once per recorded output, with
  the newest trigger at the output and the other inputs as they stood when
  that trigger arrived.

An output counts as reproduced when the answer paired with it equals it
field for field (the spec's ``ignore`` fields aside: ``debug``, the
evaluation record) — bit for bit, as at θ = 0. The floor judges that by a
plain equality of the two as canonical JSON (sorted keys; NaN as ``NaN``),
not by the comparator extraction is judged by: a fault in that comparator
cannot lift extraction and its floor together.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from astaa_deft.analysis.deft.planner_section import replay_module_of
from astaa_deft.analysis.deft.replay import make_planner
from astaa_deft.engine.spec.loader import load_spec
from astaa_deft.io.codecs import get_codec
from astaa_deft.io.codecs.base import DecodeError
from astaa_deft.io.log.reader import LoggedMessage, read_log

from zoo.generate import MODULE, Stack


@dataclass(frozen=True)
class Floor:
    outputs: int  # recorded outputs of the module
    reproduced: tuple[bool, ...]  # per recorded output (log order): the best plain replay's answer equals it
    way: str  # the plain replay that did best (at_trigger, at_output, output_trigger)
    steps: int  # steps that replay took
    seconds: float  # wall time of that replay: reading the log, decoding, stepping
    ways: dict[str, int] = field(default_factory=dict)  # outputs each plain way reproduced

    @property
    def count(self) -> int:
        return sum(self.reproduced)


def output_key(message: LoggedMessage) -> tuple[int, bytes]:
    """A recorded output's identity across readings of the log (its log time and bytes)."""
    return message.log_time, bytes(message.data)


@dataclass
class _Played:
    """The log as a plain replay plays it: inputs in arrival order, the recorded outputs decoded."""

    inputs: list[tuple[int, str, Any]]  # (log time, channel, decoded), log order
    outputs: list[LoggedMessage]
    expected: list[Any]  # decoded outputs (None: does not decode)


def same_output(answer: Any, recorded: Any, ignore: tuple[str, ...] | list[str]) -> bool:
    """``answer`` equals ``recorded`` bit for bit, the ``ignore`` fields aside (the zoo's: ``debug``; a spec's
    ``ignore:`` may name a nested field, ``header.frame_id``)."""
    assert all("[" not in name for name in ignore), ignore  # the zoo ignores fields of structs, no array elements

    def without(message: Any, path: list[str]) -> Any:
        if not isinstance(message, dict) or path[0] not in message:
            return message
        if len(path) == 1:
            return {k: v for k, v in message.items() if k != path[0]}
        return {**message, path[0]: without(message[path[0]], path[1:])}

    def canonical(message: Any) -> str:
        for name in ignore:
            message = without(message, name.split("."))
        return json.dumps(message, sort_keys=True)

    return canonical(answer) == canonical(recorded)


def plain_replay(stack: Stack, log_path: Path, ways: tuple[str, ...] | None = None) -> Floor:
    """The floor of ``stack``'s run in ``log_path``: the best of the plain ways (all that apply, or ``ways``)."""
    return plain_floor(stack.spec_path, MODULE, log_path, ways=ways)


def plain_floor(spec_path: Path, module: str | None, log_path: Path, *, params: dict[str, str] | None = None,
                ways: tuple[str, ...] | None = None) -> Floor:
    """The floor of any replayable module's run (``module`` in the spec's ``replay:`` section, None: its first)
    in ``log_path``, its factory made with the run's ``params``: the best of the plain ways that apply."""
    t0 = time.perf_counter()
    spec = load_spec(spec_path)
    entry = replay_module_of(spec, module)
    log = read_log(log_path)
    codecs = {name: get_codec(spec.channel(name).encoding) for name in (*entry.inputs, entry.output)}
    inputs: list[tuple[int, str, Any]] = []
    for name in entry.inputs:
        for m in log.on(spec.channel(name).key):
            try:
                inputs.append((m.log_time, name, codecs[name].decode(m.data)))
            except DecodeError:
                continue  # the module's deserialiser drops it too
    inputs.sort(key=lambda item: item[0])  # stable: equal times keep channel order
    outputs = sorted(log.on(spec.channel(entry.output).key), key=lambda m: m.log_time)
    expected = []
    for m in outputs:
        try:
            expected.append(codecs[entry.output].decode(m.data))
        except DecodeError:
            expected.append(None)
    played = _Played(inputs, outputs, expected)
    reading = time.perf_counter() - t0
    if ways is None:
        triggers = sum(1 for _, name, _ in inputs if name == entry.trigger)
        ways = ("at_trigger",) if entry.per_trigger else (
            ("at_trigger",) if triggers <= 1.5 * max(len(outputs), 1) else ()) + ("at_output", "output_trigger")
    results = []
    for way in ways:
        t1 = time.perf_counter()
        planner = make_planner(spec, dict(params or {}), entry=entry)
        try:
            answers, steps = _WAYS[way](planner, entry.trigger, played)
        finally:
            planner.close()
        reproduced = tuple(answer is not None and want is not None
                           and same_output(answer, want, entry.ignore)
                           for answer, want in zip(answers + [None] * (len(expected) - len(answers)), expected,
                                                   strict=True))
        results.append((sum(reproduced), -(time.perf_counter() - t1), way, reproduced, steps))
    count, minus_seconds, way, reproduced, steps = max(results, key=lambda r: (r[0], r[1]))
    return Floor(len(outputs), reproduced, way, steps, reading - minus_seconds, {r[2]: r[0] for r in results})


def _step(planner: Any, frame: dict[str, Any]) -> Any:
    """The module's answer to ``frame``; None when it raises on it. A factory may need an input the log holds
    only later (the OMPL planner takes no frame without the ego's state; its node never plans before one came):
    that plain replay answers nothing there and goes on, the most the floor can grant it."""
    try:
        return planner.step(frame)
    except Exception:  # noqa: BLE001 - whatever a third-party module raises on a frame it cannot take
        return None


def _at_trigger(planner: Any, trigger: str, played: _Played) -> tuple[list[Any], int]:
    newest: dict[str, Any] = {}
    answers: list[Any] = []
    steps = 0
    for _, name, message in played.inputs:
        newest[name] = message
        if name == trigger and len(answers) < len(played.outputs):
            steps += 1
            answer = _step(planner, dict(newest))
            if answer is not None:
                answers.append(answer)
    return answers, steps


def _at_output(planner: Any, trigger: str, played: _Played) -> tuple[list[Any], int]:
    newest: dict[str, Any] = {}
    answers: list[Any] = []
    cursor = steps = 0
    for out in played.outputs:
        while cursor < len(played.inputs) and played.inputs[cursor][0] <= out.log_time:
            newest[played.inputs[cursor][1]] = played.inputs[cursor][2]
            cursor += 1
        if trigger not in newest:
            answers.append(None)
            continue
        steps += 1
        answers.append(_step(planner, dict(newest)))
    return answers, steps


def _output_trigger(planner: Any, trigger: str, played: _Played) -> tuple[list[Any], int]:
    newest: dict[str, Any] = {}
    at_trigger: dict[str, Any] | None = None  # the inputs as they stood when the newest trigger arrived
    answers: list[Any] = []
    cursor = steps = 0
    for out in played.outputs:
        while cursor < len(played.inputs) and played.inputs[cursor][0] <= out.log_time:
            newest[played.inputs[cursor][1]] = played.inputs[cursor][2]
            if played.inputs[cursor][1] == trigger:
                at_trigger = dict(newest)
            cursor += 1
        if at_trigger is None:
            answers.append(None)
            continue
        steps += 1
        answers.append(_step(planner, dict(at_trigger)))
    return answers, steps


_WAYS = {"at_trigger": _at_trigger, "at_output": _at_output, "output_trigger": _output_trigger}
