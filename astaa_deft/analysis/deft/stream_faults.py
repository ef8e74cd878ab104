"""Faults applied to a module's input streams the way the wire would deliver them, and the frames that follow.

A module replayed on its DeFT frames reads, per input channel, the messages it
received in arrival order. A live test case's policy changes what arrives:
``set`` rewrites fields of a message (``hold``: of several in a row), ``drop``
takes one away, ``delay`` makes one arrive later (overtaken by the ones
after it, as on a congested link), ``reorder`` delivers one right after the
next, ``duplicate`` delivers one again right after itself. :func:`apply_fault`
does the same to the recorded streams; :func:`trigger_frames` and
:func:`output_frames` then pick each frame with DeFT's own rules
(:mod:`.frames`) over the faulted arrival times, so a reordered stamp reaches
the module exactly as it would have in the run: older data arriving last.

Pure: decoded messages and times in, new streams and frames out.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

from astaa_deft.analysis.deft.frames import (
    OutputContext, Stream, candidates, frame_at, newest_at_or_before, trigger_frame,
)
from astaa_deft.io.statefile import MAX_NAME, StateReader
from astaa_deft.model.errors import AstaaDeftError
from astaa_deft.model.fields import FieldPath, FieldPathError, set_field
from astaa_deft.model.json import DecodedMessage, FieldValue, JsonObject, JsonValue
from astaa_deft.model.vocabulary import TextEnum

MAX_LIST = 1_000_000  # items of a list a decoder reads back: far more than a search writes

DUPLICATE_GAP_NS = 1_000_000  # a copy arrives this long after the real message (the engine sends it next)
REORDER_GAP_NS = 1_000_000  # a reordered message arrives this long after the one that overtook it


class FaultKind(TextEnum):
    """What a fault does to a stream (the live action of the same name)."""

    SET = "set"  # one field of one message set to a value
    HOLD = "hold"  # one field set to a value on ``count`` messages in a row
    DROP = "drop"
    DELAY = "delay"
    DUPLICATE = "duplicate"
    REORDER = "reorder"


MESSAGE_KINDS = frozenset({FaultKind.DROP, FaultKind.DELAY, FaultKind.DUPLICATE, FaultKind.REORDER})


@dataclass(frozen=True, kw_only=True)
class StreamFault:
    """One fault on one input channel of a module, at message ``index`` (0-based, in arrival order)."""

    channel: str
    kind: FaultKind
    index: int
    path: str | None = None  # the field a set or hold writes
    value: FieldValue = None  # what it writes there
    value_ref: str | None = None  # the dictionary entry the value comes from ("@group.name"), for the live case
    count: int = 1  # messages a hold covers
    delay_ms: float = 0.0

    @property
    def family(self) -> str:
        """The fault's field family (bucket identity): the field folded to the object holding it, indices
        folded, action and value left out — ``localization:.{…}``; every message fault ``localization:(message)``,
        as the live root-cause identity folds them."""
        if self.kind in MESSAGE_KINDS or self.path is None:
            return f"{self.channel}:(message)"
        return f"{self.channel}:{field_family(self.path)}"

    def describe(self) -> str:
        if self.kind in MESSAGE_KINDS:
            extra = f" by {self.delay_ms:g} ms" if self.kind == FaultKind.DELAY else ""
            return f"{self.kind} {self.channel} #{self.index + 1}{extra}"
        value = self.value_ref or _short(self.value)
        held = f" on {self.count} messages" if self.kind == FaultKind.HOLD else ""
        return f"{self.channel}:{self.path} = {value} on #{self.index + 1}{held}"

    def to_json(self) -> JsonObject:
        return {"channel": self.channel, "kind": self.kind.value, "index": self.index, "path": self.path,
                "value": _tagged(self.value), "value_ref": self.value_ref, "count": self.count,
                "delay_ms": self.delay_ms}

    @classmethod
    def from_json(cls, r: StateReader) -> StreamFault:
        """The fault as ``to_json`` wrote it (InputError naming the file and the field when one is damaged)."""
        from astaa_deft.model.tagged import from_tagged

        channel, kind, index, path, value, value_ref, count, delay = r.fields(
            "channel", "kind", "index", "path", "value", "value_ref", "count", "delay_ms")
        try:
            decoded = from_tagged(value.value)  # type: ignore[arg-type]
        except (TypeError, ValueError) as exc:
            value.fail(f"is not a field value ({exc})")
        kinds = tuple(k.value for k in FaultKind)
        return cls(channel=channel.string(MAX_NAME), kind=FaultKind(kind.string(choices=kinds)), index=index.whole(),
                   path=path.text(MAX_NAME, optional=True), value=decoded,
                   value_ref=value_ref.text(MAX_NAME, optional=True), count=count.whole(1), delay_ms=delay.real(0))


def _tagged(value: FieldValue) -> JsonValue:
    from astaa_deft.model.tagged import to_tagged

    return to_tagged(value)


def _short(value: object, limit: int = 40) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[:limit - 1] + "…"


def field_family(path: str) -> str:
    """``pose.x`` → ``pose.{…}``, ``points[3].v`` → ``points[].{…}``, ``speed`` → ``.{…}`` (the message itself)."""
    try:
        parsed = FieldPath.parse(path)
    except FieldPathError:
        return path
    owner: list[str] = []
    for segment in parsed.segments[:-1]:
        if isinstance(segment, str):
            owner.append(segment)
        elif owner:
            owner[-1] += "[]"
    return ".".join(owner) + ".{…}"


@dataclass(frozen=True, kw_only=True)
class Received:
    """One message a module received: when, what, and which recorded message it is (``origin``, ``copy``)."""

    time_ns: int
    message: DecodedMessage
    origin: int  # index into the channel's recorded stream
    copy: int = 0  # 0: the message as recorded or rewritten; n: the n-th extra copy (a duplicate)
    rewritten: bool = False  # a set or hold changed its fields

    @property
    def key(self) -> tuple[int, int, bool]:
        return (self.origin, self.copy, self.rewritten)


Streams = Mapping[str, Sequence[Received]]


def recorded_streams(messages: Mapping[str, Sequence[tuple[int, DecodedMessage]]]) -> dict[str, list[Received]]:
    """Per channel, (arrival time, decoded message) as recorded → the module's streams."""
    return {name: [Received(time_ns=t, message=m, origin=i) for i, (t, m) in enumerate(msgs)]
            for name, msgs in messages.items()}


class FaultNotApplicable(AstaaDeftError, ValueError):
    """The fault does not fit these streams (no such message, no such field): the search skips it (internal)."""


def apply_fault(streams: Streams, fault: StreamFault) -> dict[str, list[Received]]:
    """The streams the module receives under ``fault``, in arrival order (the others unchanged, shared)."""
    out = {name: list(stream) for name, stream in streams.items()}
    if fault.channel not in out:
        raise FaultNotApplicable(f"the module does not read {fault.channel}")
    stream = out[fault.channel]
    if not 0 <= fault.index < len(stream):
        raise FaultNotApplicable(f"{fault.channel} has no message #{fault.index + 1}")
    target = stream[fault.index]
    if fault.kind in (FaultKind.SET, FaultKind.HOLD):
        assert fault.path is not None
        last = fault.index + (fault.count if fault.kind == FaultKind.HOLD else 1)
        for i in range(fault.index, min(last, len(stream))):
            message = copy.deepcopy(stream[i].message)
            try:
                changed = set_field(message, fault.path, copy.deepcopy(fault.value))
            except (FieldPathError, TypeError, ValueError, KeyError, IndexError) as exc:
                raise FaultNotApplicable(f"{fault.channel}:{fault.path}: {exc}") from None
            if not changed:
                if i == fault.index:
                    raise FaultNotApplicable(f"{fault.channel} #{i + 1} has no field {fault.path}")
                continue
            stream[i] = replace(stream[i], message=message, rewritten=True)
        return out
    if fault.kind == FaultKind.DROP:
        del stream[fault.index]
    elif fault.kind == FaultKind.DELAY:
        stream[fault.index] = replace(target, time_ns=target.time_ns + int(fault.delay_ms * 1e6))
    elif fault.kind == FaultKind.DUPLICATE:
        stream.append(Received(time_ns=target.time_ns + DUPLICATE_GAP_NS, message=target.message,
                               origin=target.origin, copy=1))
    elif fault.kind == FaultKind.REORDER:
        if fault.index + 1 >= len(stream):
            raise FaultNotApplicable(f"{fault.channel} #{fault.index + 1} has no next message to overtake it")
        overtaking = stream[fault.index + 1]
        stream[fault.index] = replace(target, time_ns=overtaking.time_ns + REORDER_GAP_NS)
    stream.sort(key=lambda r: r.time_ns)  # stable: simultaneous messages keep their order
    return out


def smaller_faults(fault: StreamFault) -> list[StreamFault]:
    """Smaller forms of ``fault``, smallest first: a hold on one message (a set), then on fewer messages. A
    set or a message fault is one message already: none (a shorter delay is not smaller: it only moves the
    message nearer the edge where its overtaking depends on the live run's jitter)."""
    if fault.kind == FaultKind.HOLD:
        counts = sorted({1, *(fault.count // 2 ** k for k in range(1, 5))} - {0, fault.count})
        return [replace(fault, kind=FaultKind.SET, count=1) if count == 1 else replace(fault, count=count)
                for count in counts]
    return []


Frame = dict[str, Received]  # input channel → the message the module reads in that frame


def trigger_frames(streams: Streams, trigger: str) -> list[Frame]:
    """A per-trigger module's frames: one per trigger message, each other input its newest at or before it
    (never older than in the previous frame; an input not heard from yet left out)."""
    times = {name: Stream(name, [r.time_ns for r in stream]) for name, stream in streams.items()}
    previous: dict[str, int] = {}
    out: list[Frame] = []
    for t_index in range(len(streams[trigger])):
        picked = trigger_frame(times, trigger, t_index, previous)
        previous = picked
        out.append({name: streams[name][i] for name, i in picked.items()})
    return out


def output_frames(streams: Streams, trigger: str, output_times: Sequence[int], lookback_ns: int
                  ) -> list[Frame | None]:
    """A module replayed per recorded output (the planner): the most likely frame of each output (open
    loop: at the recorded output times), by the rule the minimiser's replay uses; None where an input had
    no message yet."""
    times = {name: Stream(name, [r.time_ns for r in stream]) for name, stream in streams.items()}
    trigger_times = times[trigger].times
    previous: dict[str, int] = {}
    out: list[Frame | None] = []
    for output_ns in output_times:
        t_index = newest_at_or_before(trigger_times, output_ns)
        if t_index < 0:
            out.append(None)
            continue
        choice = frame_at(times, trigger, t_index, trigger_times[t_index], previous)
        if choice is None:
            options = candidates(OutputContext(streams=times, trigger=trigger, output_ns=output_ns, previous=previous,
                                               lookback_ns=lookback_ns))
            if not options:
                out.append(None)
                continue
            choice = dict(options[0].choice)
        previous = choice
        out.append({name: streams[name][i] for name, i in choice.items()})
    return out


def frame_key(frame: Frame | None) -> tuple[tuple[str, tuple[int, int, bool]], ...] | None:
    """What identifies a frame's inputs (two frames with the same key feed the module the same messages)."""
    if frame is None:
        return None
    return tuple(sorted((name, r.key) for name, r in frame.items()))


def frame_origins(frame: Frame | None) -> tuple[tuple[str, int, int, int], ...] | None:
    """Which recorded messages a frame holds, and when they arrived (not whether a field of them changed)."""
    if frame is None:
        return None
    return tuple(sorted((name, r.origin, r.copy, r.time_ns) for name, r in frame.items()))


def first_changed(baseline: Sequence[Frame | None], faulted: Sequence[Frame | None]) -> int | None:
    """The first frame index where the faulted frames differ from the baseline's (None: identical)."""
    for k in range(max(len(baseline), len(faulted))):
        a = frame_key(baseline[k]) if k < len(baseline) else ("absent",)
        b = frame_key(faulted[k]) if k < len(faulted) else ("absent",)
        if a != b:
            return k
    return None


# -- field-read probes ---------------------------------------------------------------------------------


def leaf_paths(message: object, prefix: str = "") -> list[str]:
    """Every leaf of a decoded message as a field path, array elements folded to ``[*]`` (each once)."""
    found: dict[str, None] = {}
    _leaves(message, prefix, found)
    return list(found)


def _leaves(value: object, prefix: str, found: dict[str, None]) -> None:
    if isinstance(value, Mapping):
        for key, item in value.items():
            if isinstance(key, str) and key.isidentifier():
                _leaves(item, f"{prefix}.{key}" if prefix else key, found)
    elif isinstance(value, list):
        for item in value:
            _leaves(item, f"{prefix}[*]", found)
    elif prefix:
        found.setdefault(prefix, None)


PERTURBATIONS = 2  # a field is probed up and down: a module may read it on one side of a threshold only


def perturbed(value: object, way: int = 0) -> FieldValue | None:
    """A value a module reading this field would notice, the ``way``-th of :data:`PERTURBATIONS` (0: up, 1:
    down); None: nothing to perturb that way."""
    if isinstance(value, bool):
        return not value if way == 0 else None
    if isinstance(value, int):
        return value + 7 + abs(value) // 2 if way == 0 else value // 2 - 3
    if isinstance(value, float):
        if not math.isfinite(value):
            return 0.5 if way == 0 else None
        return value + 1.25 + abs(value) * 0.37 if way == 0 else value * 0.5 - 1.25
    if isinstance(value, str):
        return value + "~" if way == 0 else ("" if value else None)
    return None


def perturb_field(streams: Streams, channel: str, path: str, way: int = 0) -> dict[str, list[Received]] | None:
    """The streams with ``channel``'s field ``path`` perturbed the ``way``-th way in every message (None: no
    message has it)."""
    out = {name: list(stream) for name, stream in streams.items()}
    touched = False
    for i, received in enumerate(out[channel]):
        message = copy.deepcopy(received.message)
        changed = False
        for concrete, old in _concrete(message, path):
            new = perturbed(old, way)
            if new is not None and set_field(message, concrete, new):
                changed = True
        if changed:
            out[channel][i] = replace(received, message=message, rewritten=True)
            touched = True
    return out if touched else None


def _concrete(message: DecodedMessage, path: str) -> list[tuple[FieldPath, object]]:
    from astaa_deft.model.fields import get

    try:
        return [(p, v) for p, v in get(message, path)]
    except FieldPathError:
        return []


@dataclass(frozen=True, kw_only=True)
class FieldReads:
    """Which input fields of one module change any of its outputs in the baseline's frames."""

    module: str
    read: tuple[tuple[str, str], ...]  # (channel, field path) whose perturbation changed an output
    unread: tuple[tuple[str, str], ...]  # perturbed in every message: no output changed
    probed_frames: int = 0
    seconds: float = 0.0
    notes: tuple[str, ...] = field(default_factory=tuple)

    def to_json(self) -> JsonObject:
        return {"module": self.module, "read": [list(p) for p in self.read], "unread": [list(p) for p in self.unread],
                "probed_frames": self.probed_frames, "seconds": round(self.seconds, 3), "notes": list(self.notes)}

    @classmethod
    def from_json(cls, r: StateReader) -> FieldReads:
        """The reads as ``to_json`` wrote them (InputError naming the file and the field when one is damaged)."""
        module, read, unread, frames, seconds, notes = r.fields(
            "module", "read", "unread", "probed_frames", "seconds", "notes")
        return cls(module=module.string(MAX_NAME), read=field_pairs(read), unread=field_pairs(unread),
                   probed_frames=frames.whole(), seconds=seconds.real(0),
                   notes=tuple(notes.each(lambda v: v.string(), MAX_LIST)))


def field_pairs(r: StateReader) -> tuple[tuple[str, str], ...]:
    """A list of [channel, field] pairs, as ``FieldReads.to_json`` writes them."""
    def pair(v: StateReader) -> tuple[str, str]:
        parts = v.each(lambda part: part.string(MAX_NAME), 2)
        if len(parts) != 2:
            v.fail("must be a [channel, field] pair")
        return parts[0], parts[1]

    return tuple(r.each(pair, MAX_LIST))


def fields_nothing_reads(consumers: Mapping[str, Sequence[str]], reads: Sequence[FieldReads]
                         ) -> list[tuple[str, str]]:
    """(channel, field) that no module reads: every consumer of the channel was probed (a replayable module
    that reads the channel) and none of them read the field. A channel any other module consumes keeps every
    field (that module is not replayed: its reading is unknown)."""
    probed = {r.module: r for r in reads}
    unread: dict[tuple[str, str], None] = {}
    for r in reads:
        for pair in r.unread:
            channel = pair[0]
            who = consumers.get(channel, ())
            if not who or any(m not in probed for m in who):
                continue
            if all(pair in probed[m].unread for m in who):
                unread.setdefault(pair, None)
    return sorted(unread)


def target_path_matches(generation_path: str, probed_path: str) -> bool:
    """Whether a generation target's field (``points[*].x``, ``points[].x`` or ``points[0].x``) is the probed
    leaf (``points[*].x``): array indices compared folded."""
    return _folded(generation_path) == _folded(probed_path)


def _folded(path: str) -> str:
    import re

    return re.sub(r"\[[^\]]*\]", "[*]", path)
