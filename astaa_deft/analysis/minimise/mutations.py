"""The mutations of an intercepted run, and what a module received with any subset of them.

An intercepted log holds, per mutated delivery, three cross-referenced
records (docs/policies.md, "Mutation events"): the event on
``/astaa/mutations``, the real message on ``/astaa/original/<key>`` and what
was delivered on the key's own topic. Untouched messages of an intercepted
channel are on the key's topic without an event. This module turns that into
:class:`Mutation` objects — the items the minimiser works on — and rebuilds,
for one module and any subset of mutations, the message streams that module
would have received: kept mutations as delivered, the others reverted to the
real message (a reverted drop puts the message back; a reverted delay puts it
back at its arrival time; a reverted duplicate or injection disappears).

Who got a delivery. When a policy narrows its consumers, the engine splits a
message: the affected consumers get the mutated copy, the others an
untouched one (logged without an event), and policies after that act on both
copies, so one real message may come out as several deliveries. An event
records the consumers at the moment its last step ran, which can be wider
than who got the delivery in the end. The deliveries of one real message
partition its consumers and the recorded sets are nested or disjoint (each
split only narrows), so each consumer belongs to the delivery with the
smallest recorded set holding it; the consumers no event holds got the
untouched copy. :attr:`Mutation.consumers` is that corrected set, and it is
what the restricted test case names, so replay and live runs agree.
"""

from __future__ import annotations

import json
import statistics
from bisect import bisect_left, bisect_right
from collections import defaultdict
from collections.abc import Hashable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from astaa_deft.io.codecs import get_codec
from astaa_deft.io.codecs.base import DecodeError, EncodeError
from astaa_deft.model.errors import InputError, Problem
from astaa_deft.model.fields import FieldPath, FieldPathError, set_field
from astaa_deft.engine.intercept.actions import ACTIONS
from astaa_deft.engine.intercept.actions.base import ActionDetail
from astaa_deft.model.records import FieldChange, RecordError
from astaa_deft.model.tagged import from_tagged
from astaa_deft.io.log import layout
from astaa_deft.io.log import records as rec
from astaa_deft.io.log.reader import LogContents, LoggedMessage
from astaa_deft.model.json import FieldValue, JsonObject
from astaa_deft.model.sut import Spec

FieldSelection = tuple[int, ...] | None
"""Which of a mutation's field changes are kept: indices into ``Mutation.fields``, or None for all."""

# What each action is, from its own flags (intercept/actions/<name>.py).
EXTRA_ACTIONS = frozenset(name for name, action in ACTIONS.items() if action.adds_delivery)  # on an extra delivery
DEFERRING_ACTIONS = frozenset(name for name, action in ACTIONS.items() if action.defers)  # delivered after arrival
FIELDS_INSEPARABLE = frozenset(name for name, action in ACTIONS.items() if not action.fields_separable)
SIBLING_WINDOW_NS = 200_000_000  # an untouched copy of a split message is logged within this of its event


@dataclass(frozen=True)
class Step:
    """One policy's part of a (possibly stacked) mutation: ``policy`` did ``action`` with ``detail``."""

    policy: str
    action: str
    detail: Mapping[str, FieldValue]  # the action's detail as logged, values untagged

    @property
    def record(self) -> ActionDetail | None:
        """The detail as its action's typed record (None for an action this version does not know)."""
        action = ACTIONS.get(self.action)
        return action.detail_type.from_json(self.detail) if action is not None else None


@dataclass(frozen=True)
class AnchorPin:
    """Where a pinned mutation's window opens: ``after`` seconds past message ``message`` of ``channel``
    (see :mod:`.anchoring`)."""

    channel: str
    message: int  # 1-based, the anchor's own count (from the run's start: it has nothing before the stack is live)
    after: float = 0.0  # 0: the mutated channel's first message after that one


@dataclass(frozen=True, kw_only=True)
class Mutation:
    """One mutated, dropped or extra delivery of an intercepted run: an item to minimise."""

    number: int  # position among the log's effective mutations, in log order: a stable id
    channel: str
    steps: tuple[Step, ...]
    consumers: tuple[str, ...]  # who got this delivery (or lost it, for a drop); see the module doc
    message_index: int  # 1-based real message index on the channel
    time: float  # seconds since run start on the interceptor's clock, when the real message arrived
    at: float  # the same moment in seconds since the run's start on the log's clock (what reports show)
    fields: tuple[FieldChange, ...]  # concrete paths, values untagged
    original: bytes  # the real message (for an injection: its template)
    original_time_ns: int  # when the real message arrived, on the log's clock
    delivered: bytes | None  # what the consumers got; None when dropped
    delivered_time_ns: int | None
    testcase: str = ""
    event: JsonObject = field(default_factory=dict, compare=False, repr=False)  # as logged
    pin: AnchorPin | None = field(default=None, compare=False)  # None: pinned by its count from the run's start

    @property
    def action(self) -> str:
        return "+".join(step.action for step in self.steps)

    @property
    def policy(self) -> str:
        return "+".join(step.policy for step in self.steps)

    @property
    def actions(self) -> frozenset[str]:
        return frozenset(step.action for step in self.steps)

    @property
    def extra(self) -> bool:
        """A copy or an injection: the real message was delivered on its own, untouched."""
        return bool(self.actions & EXTRA_ACTIONS)

    @property
    def deferred(self) -> bool:
        return bool(self.actions & DEFERRING_ACTIONS)

    @property
    def fields_reducible(self) -> bool:
        """Whether dropping some field changes still leaves a meaningful delivery (stage 3)."""
        return len(self.fields) > 1 and not self.actions & FIELDS_INSEPARABLE

    def payload(self, selection: FieldSelection, codec_name: str) -> bytes | None:
        """What is delivered when only the ``selection`` of field changes is kept (None: dropped).

        The full selection is the logged delivery byte for byte; a smaller one
        is the real message with those fields set, re-encoded.
        """
        if self.delivered is None:
            return None
        if selection is None or len(selection) == len(self.fields):
            return self.delivered
        codec = get_codec(codec_name)
        try:
            message = codec.decode(self.original)
            for index in selection:
                change = self.fields[index]
                set_field(message, FieldPath.parse(change.path), change.new)
            return codec.encode(message)
        except (DecodeError, EncodeError, FieldPathError):
            return self.delivered  # cannot take it apart: the field changes stay together

    def describe(self, selection: FieldSelection = None) -> str:
        """One line, e.g. ``set on routing #3 (to planning): speed_limit 13.0 → nan`` (policy culprit)."""
        to = f" (to {', '.join(self.consumers)})" if self.consumers else ""
        chosen = self.fields if selection is None else tuple(self.fields[i] for i in selection)
        changes = "; ".join(f"{c.path}: {_short(c.old)} → {_short(c.new)}" for c in chosen)
        details = [item for step in self.steps if step.record is not None for item in step.record.describe()]
        text = f"{self.action} on {self.channel} #{self.message_index}{to}"
        if changes:
            text += f": {changes}"
        if details:
            text += f" [{', '.join(details)}]"
        return f"{text} (policy {self.policy}, +{self.at:.2f} s)"


def _short(value: object, limit: int = 40) -> str:
    text = repr(value) if not isinstance(value, str) else json.dumps(value)
    return text if len(text) <= limit else text[:limit - 1] + "…"


@dataclass(kw_only=True)
class MutationLog:
    """Every effective mutation of a run, in log order, with the indexes stream building needs."""

    spec: Spec
    mutations: list[Mutation]
    start_ns: int  # the run's start (its run_started event)
    noop: int = 0  # events that changed nothing (e.g. a set whose fields were all skipped)
    # Per channel: deliveries on the key topic without an event (all of them on a channel
    # no policy touched), in log order.
    untouched: dict[str, list[LoggedMessage]] = field(default_factory=dict)
    # Per mutation number: the consumers of its real message that got an untouched copy.
    sibling_consumers: dict[int, tuple[str, ...]] = field(default_factory=dict)
    record_time_ns: dict[int, int] = field(default_factory=dict)  # per mutation: when its records were logged

    def by_number(self) -> dict[int, Mutation]:
        return {m.number: m for m in self.mutations}


def read_mutations(log: LogContents, spec: Spec) -> MutationLog:
    """The mutations of an intercepted run (InputError if the records do not fit together)."""
    events = [(m, _decode_event(log, n, m)) for n, m in enumerate(log.on(layout.MUTATIONS_TOPIC), start=1)]
    try:
        return _read_mutations(log, spec, events)
    except (KeyError, TypeError, ValueError, AttributeError, IndexError) as exc:
        raise InputError(Problem(str(log.path), None, None,
                                 f"a mutation event does not have the fields astaa-deft writes ({_what(exc)})",
                                 "the log is damaged or was not written by astaa-deft proxy --policy")) from None


def _decode_event(log: LogContents, number: int, record: LoggedMessage) -> dict:
    """One record on the mutations topic as JSON, or an InputError that says which and where."""
    where = f"mutation event {number} (log time {record.log_time / 1e9:.3f} s)"
    try:
        text = record.data.decode("utf-8")
        body = json.loads(text)
    except UnicodeDecodeError as exc:
        raise InputError(Problem(str(log.path), None, None, f"{where} is not UTF-8 text (byte {exc.start})",
                                 "the log is damaged; re-record the run")) from None
    except json.JSONDecodeError as exc:
        raise InputError(Problem(str(log.path), None, None,
                                 f"{where} is not valid JSON: {exc.msg} at line {exc.lineno} column {exc.colno}",
                                 "the log is damaged; re-record the run")) from None
    except RecursionError:
        raise InputError(Problem(str(log.path), None, None, f"{where} is nested too deeply",
                                 "the log is damaged; re-record the run")) from None
    if not isinstance(body, dict):
        raise InputError(Problem(str(log.path), None, None, f"{where} is not a JSON object",
                                 "the log is damaged; re-record the run"))
    return body


def _what(exc: BaseException) -> str:
    if isinstance(exc, KeyError):
        return f"'{exc.args[0]}' is missing" if exc.args else "a key is missing"
    return "a field has the wrong kind of value"


def _read_mutations(log: LogContents, spec: Spec, events: list[tuple[LoggedMessage, dict]]) -> MutationLog:
    start_ns = run_start_ns(log)
    by_topic: dict[str, dict[int, LoggedMessage]] = {}

    def message(topic: str, sequence: int | None) -> LoggedMessage | None:
        if sequence is None:
            return None
        if topic not in by_topic:
            by_topic[topic] = {m.sequence: m for m in log.on(topic)}
        found = by_topic[topic].get(int(sequence))
        if found is None:
            raise InputError(Problem(str(log.path), None, None,
                                     f"a mutation event names message {sequence} of '{topic}', which the log lacks",
                                     "the log is truncated or was not written by astaa-deft"))
        return found

    known = {c.name: c for c in spec.channels}
    raw: list[tuple[LoggedMessage, rec.MutationRecord, dict, LoggedMessage, LoggedMessage | None]] = []
    noop = 0
    delivered_seqs: dict[str, set[int]] = defaultdict(set)
    for record, body in events:
        if not isinstance(body, Mapping):
            raise InputError(Problem(str(log.path), None, None, "a mutation event is not a JSON object",
                                     "the log is damaged or was not written by astaa-deft"))
        event = rec.MutationRecord.from_json(body, time_ns=record.log_time, where=str(log.path))
        channel = known.get(event.channel)
        if channel is None:
            raise InputError(Problem(str(log.path), None, None,
                                     f"a mutation event names channel '{event.channel}', "
                                     f"which spec '{spec.name}' does not declare",
                                     "give the spec the run was recorded with"))
        if event.delivered_sequence is not None:
            delivered_seqs[channel.name].add(event.delivered_sequence)
        original = message(layout.ORIGINAL_PREFIX + channel.key, event.original_sequence)
        if original is None:  # nothing was changed, dropped or added: not a mutation in effect
            noop += 1
            continue
        delivered = message(channel.key, event.delivered_sequence)
        raw.append((record, event, dict(body), original, delivered))

    offset_ns = _clock_offset(raw, start_ns, interceptor_epoch_ns(log))
    mutations = []
    record_times = {}
    for number, (record, event, body, original, delivered) in enumerate(raw):
        steps = _steps(event)
        deferred = any(s.action in DEFERRING_ACTIONS for s in steps)
        time_s = event.time
        arrived_ns = offset_ns + round(time_s * 1e9) if deferred else original.log_time
        mutations.append(Mutation(
            number=number, channel=event.channel, steps=steps,
            consumers=event.consumers, message_index=event.message_index,
            time=time_s, at=(arrived_ns - start_ns) / 1e9,
            fields=tuple(change.untagged() for change in event.fields),
            original=original.data,
            original_time_ns=arrived_ns,
            delivered=delivered.data if delivered is not None else None,
            delivered_time_ns=delivered.log_time if delivered is not None else None,
            testcase=event.testcase, event=body))
        record_times[number] = record.log_time

    untouched = {}
    for channel in spec.channels:
        if channel.key in log.channels:
            skip = delivered_seqs.get(channel.name, set())
            untouched[channel.name] = [m for m in log.on(channel.key) if m.sequence not in skip]
    mutations, siblings = _assign_consumers(mutations, spec)
    return MutationLog(spec=spec, mutations=mutations, start_ns=start_ns, noop=noop, untouched=untouched,
                       sibling_consumers=siblings, record_time_ns=record_times)


def _steps(event: rec.MutationRecord) -> tuple[Step, ...]:
    policies = event.policy.split("+")
    actions = event.action.split("+")
    detail = _logged_object(from_tagged(event.detail or {}), event)
    if len(actions) == 1:
        return (Step(policies[0], actions[0], detail),)
    parts = detail.get("steps") or [{} for _ in actions]
    if not isinstance(parts, Sequence):
        raise _damaged_detail(event)
    # Not strict: a damaged event's shorter list yields fewer steps, as it always has.
    return tuple(Step(p, a, _logged_object(_logged_object(part, event).get("detail") or {}, event))
                 for p, a, part in zip(policies, actions, parts, strict=False))


def _logged_object(value: FieldValue, event: rec.MutationRecord) -> Mapping[str, FieldValue]:
    """A logged detail (or step) that must be an object; RecordError if the log holds something else."""
    if not isinstance(value, Mapping):
        raise _damaged_detail(event)
    return value


def _damaged_detail(event: rec.MutationRecord) -> RecordError:
    return RecordError(Problem("the log", None, None,
                               f"a damaged record: the detail of a {event.action} mutation on '{event.channel}' "
                               f"(message {event.message_index}) is not an object",
                               "the file was cut or altered; record the run again"))


def run_start_ns(log: LogContents) -> int:
    """The run's start: its run_started event, else (an event lost to the recorder) its first bus message."""
    started = [r.time_ns for r in map(rec.decode, log.events("run_started"))
               if isinstance(r, rec.RunStarted) and r.time_ns]
    if started:
        return started[0]
    bus = [m.log_time for m in log.messages if not m.topic.startswith("/astaa/")]
    return min(bus) if bus else 0


def interceptor_epoch_ns(log: LogContents) -> int | None:
    """Where the interceptor's clock starts on the log's clock (the run_started event says), if known."""
    for r in map(rec.decode, log.events("run_started")):
        if isinstance(r, rec.RunStarted) and r.interceptor_epoch_ns:
            return int(r.interceptor_epoch_ns)
    return None


def _clock_offset(raw: Sequence[tuple[LoggedMessage, rec.MutationRecord, dict, LoggedMessage, Any]],
                  start_ns: int, epoch_ns: int | None = None) -> int:
    """Log time minus interceptor time.

    A delayed or reordered message is logged when it was delivered; its
    arrival is known only on the interceptor's clock (``time``). The log
    says where that clock starts (``RunStarted.interceptor_epoch_ns``). Older
    logs: the median offset of the mutations delivered the moment their
    message arrived; with none, the run's start — a guess late by the time
    the recorder took to start, enough to put a reverted delayed message
    after its successor (one campaign's delay bucket "failed without any
    mutation" that way).
    """
    if epoch_ns is not None:
        return epoch_ns
    offsets = [record.log_time - round(event.time * 1e9)
               for record, event, _, _, _ in raw
               if not (set(event.action.split("+")) & (DEFERRING_ACTIONS | EXTRA_ACTIONS))]
    return int(statistics.median(offsets)) if offsets else start_ns


def _assign_consumers(mutations: list[Mutation], spec: Spec) -> tuple[list[Mutation], dict[int, tuple[str, ...]]]:
    """Correct each delivery's consumers (module doc), and note who got an untouched copy instead."""
    groups: dict[tuple[str, int], list[Mutation]] = defaultdict(list)
    for m in mutations:
        if not m.extra:
            groups[(m.channel, m.message_index)].append(m)
    fixed: dict[int, tuple[str, ...]] = {}
    siblings: dict[int, tuple[str, ...]] = {}
    for (channel, _), group in groups.items():
        everyone = spec.channel(channel).consumers
        owner: dict[str, Mutation] = {}
        for consumer in everyone:
            holding = [m for m in group if consumer in m.consumers]
            if holding:  # the smallest recorded set; on a tie the later delivery
                owner[consumer] = min(reversed(holding), key=lambda m: len(m.consumers))
        untouched = tuple(c for c in everyone if c not in owner)
        for m in group:
            fixed[m.number] = tuple(c for c in everyone if owner.get(c) is m) or m.consumers
            siblings[m.number] = untouched
    out = [m if m.number not in fixed else _with_consumers(m, fixed[m.number]) for m in mutations]
    return out, siblings


def _with_consumers(m: Mutation, consumers: tuple[str, ...]) -> Mutation:
    from dataclasses import replace

    return m if consumers == m.consumers else replace(m, consumers=consumers)


# ---------------------------------------------------------------- streams


@dataclass(frozen=True)
class Delivered:
    """One message a module received: when, what, and where it comes from (``key``, for caching)."""

    time_ns: int
    data: bytes
    key: Hashable  # ("log", sequence) | ("original", number) | ("mutation", number, selection)


class ReceivedStreams:
    """What ``module`` received on ``channels``, rebuilt for any subset of the mutations.

    ``relevant`` lists the mutations that changed what the module received;
    every other mutation cannot change its streams and is ignored by
    :meth:`build`.
    """

    def __init__(self, mlog: MutationLog, module: str, channels: Iterable[str]):
        self.mlog = mlog
        self.module = module
        self.channels = tuple(channels)
        codec_names = {c.name: c.encoding for c in mlog.spec.channels}
        self.codec_names = {name: codec_names[name] for name in self.channels}
        self.relevant = [m for m in mlog.mutations if m.channel in self.channels and module in m.consumers]
        claimed = claim_siblings(mlog, self.relevant)
        self._base: dict[str, list[Delivered]] = {}
        for name in self.channels:
            messages = mlog.untouched.get(name)
            if messages is None:
                continue
            self._base[name] = [Delivered(m.log_time, m.data, ("log", name, m.sequence))
                                for m in messages if (name, m.sequence) not in claimed]
        self._by_channel: dict[str, list[Mutation]] = defaultdict(list)
        for m in self.relevant:
            self._by_channel[m.channel].append(m)

    def has(self, channel: str) -> bool:
        return channel in self._base or channel in self._by_channel

    def build(self, kept: Mapping[int, FieldSelection]) -> dict[str, list[Delivered]]:
        """Per channel, the module's messages in arrival order with ``kept`` mutations applied."""
        out: dict[str, list[Delivered]] = {}
        for name in self.channels:
            stream = list(self._base.get(name, ()))
            for m in self._by_channel.get(name, ()):
                if m.number in kept:
                    selection = _normal(kept[m.number], m)
                    data = m.payload(selection, self.codec_names[name])
                    if data is not None:
                        stream.append(Delivered(m.delivered_time_ns or m.original_time_ns, data,
                                                ("mutation", m.number, selection)))
                elif not m.extra:
                    stream.append(Delivered(m.original_time_ns, m.original, ("original", m.number)))
            stream.sort(key=lambda d: d.time_ns)  # stable: simultaneous messages keep log order
            out[name] = stream
        return out


def claim_siblings(mlog: MutationLog, mutations: Iterable[Mutation]) -> set[tuple[str, int]]:
    """(channel, sequence) of the untouched copies that split messages of ``mutations`` left in the log.

    One per real message: the logged untouched delivery with the same bytes
    as the real message, nearest in time to the mutation's records.
    """
    claimed: set[tuple[str, int]] = set()
    done: set[tuple[str, int]] = set()
    by_time: dict[str, tuple[list[int], list[LoggedMessage]]] = {}
    for m in mutations:
        if m.extra or not mlog.sibling_consumers.get(m.number) or (m.channel, m.message_index) in done:
            continue
        done.add((m.channel, m.message_index))
        if m.channel not in by_time:
            ordered = sorted(mlog.untouched.get(m.channel, ()), key=lambda c: c.log_time)
            by_time[m.channel] = ([c.log_time for c in ordered], ordered)
        times, ordered = by_time[m.channel]
        record_ns = mlog.record_time_ns[m.number]
        best = None
        for candidate in ordered[bisect_left(times, record_ns - SIBLING_WINDOW_NS):
                                 bisect_right(times, record_ns + SIBLING_WINDOW_NS)]:
            gap = abs(candidate.log_time - record_ns)
            if (candidate.data == m.original and (m.channel, candidate.sequence) not in claimed
                    and (best is None or gap < best[0])):
                best = (gap, candidate)
        if best is not None:
            claimed.add((m.channel, best[1].sequence))
    return claimed


def _normal(selection: FieldSelection, m: Mutation) -> FieldSelection:
    if selection is None or len(selection) == len(m.fields):
        return None
    return tuple(sorted(selection))


def sent_stream(mlog: MutationLog, log: LogContents, channel: str) -> list[LoggedMessage]:
    """What the channel's producer published, once per real message: originals in place of mutations."""
    key = mlog.spec.channel(channel).key
    if channel not in mlog.untouched:
        return sorted(log.on(key), key=lambda m: m.log_time)
    mutated = [m for m in mlog.mutations if m.channel == channel and not m.extra]
    siblings = claim_siblings(mlog, mutated)
    out = [m for m in mlog.untouched[channel] if (channel, m.sequence) not in siblings]
    seen: set[int] = set()
    for m in mutated:
        if m.message_index in seen:
            continue
        seen.add(m.message_index)
        out.append(LoggedMessage(key, m.original_time_ns, m.original_time_ns, 0, m.original))
    out.sort(key=lambda m: m.log_time)
    return [LoggedMessage(m.topic, m.log_time, m.publish_time, i, m.data) for i, m in enumerate(out, start=1)]
