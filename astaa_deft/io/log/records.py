"""Typed records of the run's event stream: one type per event, each owning its log form.

Every event the tool writes to ``/astaa/events`` (and shows on the console)
is one of the frozen dataclasses below or one of the model's records
(``RunEnd``, ``ProcessExit``, ``Violation``, ``RunVerdict``). Each type owns
its JSON form — ``to_json()`` writes the body, ``from_json(body, where=…)``
reads it back — and :func:`encode` / :func:`decode` only add or read the
``kind`` and ``time_ns`` that every event carries, looking the type up by its
``kind``. Readers work on records, never on the raw dicts, so a field's name
lives in one place.

The on-disk shape is the one earlier logs already have (a JSON object with a
``kind`` and a ``time_ns``), so existing logs stay readable. A record may carry
``"format": N``; a log written by a newer tool (``N`` > :data:`FORMAT`) is
refused with a clear message instead of being half understood.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, fields
from typing import Any, ClassVar, TypeVar, cast
from collections.abc import Mapping

from astaa_deft.model.errors import InputError, Problem
from astaa_deft.model.json import FieldValue, JsonObject, JsonValue
from astaa_deft.model.json_fields import JsonFields
from astaa_deft.model.records import (
    FieldChange, Mutation, MutationRow, ProcessExit, RecordError, RunEnd, RunVerdict, TaggedFieldChange, Violation,
)

FORMAT = 1  # bump when a record's meaning changes; decode() refuses newer ones

SimpleT = TypeVar("SimpleT", bound="_Simple")


class _Simple:
    """A record whose log form is its dataclass fields in order (tuples as lists), read back field by field."""

    def to_json(self) -> JsonObject:
        body: JsonObject = {}
        for f in fields(self):  # type: ignore[arg-type]  # every subclass is a dataclass
            value = getattr(self, f.name)
            body[f.name] = list(value) if isinstance(value, tuple) else value
        return body

    @classmethod
    def from_json(cls: type[SimpleT], body: Mapping[str, Any], *, where: str = "the log") -> SimpleT:
        """The record of its log form; RecordError if a required field is missing (the dataclass checks)."""
        values: dict[str, Any] = {}
        for f in fields(cls):  # type: ignore[arg-type]  # every subclass is a dataclass
            if f.name in body:
                value = body[f.name]
                values[f.name] = tuple(value) if isinstance(value, list) else value
        try:
            return cls(**values)
        except TypeError:  # a required field missing
            raise RecordError(Problem(where, None, None, f"a damaged record: a {cls.__name__} lacks a field",
                                      "the file was cut or altered; record the run again")) from None


@dataclass(frozen=True, kw_only=True)
class RunStarted(_Simple):
    time_ns: int
    mode: str
    spec: str
    command_line: tuple[str, ...] = ()
    # The interceptor's clock origin on the log's clock (ns): a mutation event's ``time`` counts from it. A
    # delayed message's arrival is known only on that clock (minimise reverts it to there). None: no
    # interceptor, or a log from before this field (then the run's start is the best guess).
    interceptor_epoch_ns: int | None = None
    kind: ClassVar[str] = "run_started"


@dataclass(frozen=True)
class RunStopping(_Simple):
    """The run's end: the monitors' horizon (nothing after it is judged)."""
    time_ns: int
    kind: ClassVar[str] = "run_stopping"


@dataclass(frozen=True)
class RunStopped(_Simple):
    time_ns: int
    kind: ClassVar[str] = "run_stopped"


@dataclass(frozen=True)
class UndeclaredKey(_Simple):
    time_ns: int
    module: str
    key: str
    note: str = ""
    kind: ClassVar[str] = "undeclared_key"


def _as_written(value: FieldValue) -> JsonValue:
    return cast(JsonValue, value)  # a logged mutation's values are already in their tagged form


@dataclass(frozen=True, kw_only=True)
class MutationRecord:
    """A ``model.records.Mutation`` as the log holds it (``policy``/``action`` joined by '+' when stacked).

    The log adds the time and the sequence numbers of the original and the
    delivered message, and keeps the values of ``fields`` and ``detail`` in
    their tagged JSON form (``model.tagged``), as written. Logged on the
    mutations topic (without kind/time_ns: :meth:`logged` is what the
    recorder writes there) and handed to ``on_event`` live.
    """
    time_ns: int
    policy: str
    action: str
    channel: str
    message_index: int = 0  # 1-based index of the real message on its channel
    fields: tuple[TaggedFieldChange, ...] = ()
    testcase: str = ""
    consumers: tuple[str, ...] = ()
    time: float = 0.0  # seconds since the run's start, when the real message arrived
    detail: JsonValue = None
    original_sequence: int | None = None
    delivered_sequence: int | None = None
    kind: ClassVar[str] = "mutation"

    @classmethod
    def of(cls, mutation: Mutation, time_ns: int) -> MutationRecord:
        """The record of a live mutation: its values in their tagged JSON form, as the log holds them."""
        body = mutation.to_json()
        return cls(time_ns=time_ns, policy=mutation.policy, action=mutation.action, channel=mutation.channel,
                   message_index=mutation.message_index, fields=tuple(change.tagged() for change in mutation.fields),
                   testcase=mutation.testcase, consumers=mutation.consumers, time=mutation.time, detail=body["detail"])

    @staticmethod
    def logged(mutation: JsonObject, original_sequence: int | None, delivered_sequence: int | None) -> JsonObject:
        """The mutations topic's body: a mutation's JSON form (``Mutation.row_json``, a dict of its own, which
        this extends) and the two sequence numbers, last, as they always were."""
        mutation["original_sequence"], mutation["delivered_sequence"] = original_sequence, delivered_sequence
        return mutation

    def to_json(self) -> JsonObject:
        """Its body on the mutations topic (the events topic adds ``kind`` and ``time_ns`` first)."""
        row: MutationRow = (self.testcase, self.policy, self.action, self.channel, self.consumers,
                            self.message_index, self.time, [(c.path, c.old, c.new) for c in self.fields],
                            self.detail)  # type: ignore[assignment]  # values already tagged: row_json passes them
        return MutationRecord.logged(Mutation.row_json(row, _as_written), self.original_sequence,
                                     self.delivered_sequence)

    @classmethod
    def from_json(cls, body: Mapping[str, JsonValue], *, time_ns: int = 0, where: str = "the log") -> MutationRecord:
        """The record of its body (the mutations topic's has no ``kind``; its time is the message's,
        ``time_ns``); RecordError if a field change is not an object."""
        read = JsonFields(body)
        return cls(time_ns=time_ns or read.integer("time_ns"), policy=read.text("policy"), action=read.text("action"),
                   channel=read.text("channel"), message_index=read.integer("message_index"),
                   fields=tuple(TaggedFieldChange.from_json(c, where=where) for c in read.objects("fields")),
                   testcase=read.text("testcase"), consumers=read.texts("consumers"), time=read.number("time"),
                   detail=read.raw("detail"), original_sequence=read.optional_integer("original_sequence"),
                   delivered_sequence=read.optional_integer("delivered_sequence"))


@dataclass(frozen=True, kw_only=True)
class PolicyApplicationsRecord(_Simple):
    """What one policy of the run's test case did, logged once at the run's end.

    ``untouched_reason`` says why a policy touched no message (its window
    never opened, its channel was silent or came late, the run ended first);
    None when it touched one.
    """
    time_ns: int
    testcase: str
    policy: str
    action: str = ""
    window_start_s: float | None = None
    window_end_s: float | None = None
    anchor: str | None = None
    in_window: int = 0
    touched: int = 0
    run_end_s: float = 0.0
    traffic: tuple[JsonValue, ...] = ()  # per target channel: {channel, count, first_s, last_s}
    untouched_reason: str | None = None
    kind: ClassVar[str] = "policy_applications"


@dataclass(frozen=True, kw_only=True)
class FlagRecord(_Simple):
    """A payload the recorder could not decode (forwarded untouched; logged raw on the flags topic)."""
    time_ns: int
    channel: str
    sequence: int | None = None
    reason: str = ""
    size: int = 0
    kind: ClassVar[str] = "undecodable"


@dataclass(frozen=True)
class ModuleLogLine(_Simple):
    """A line a module wrote on stdout or stderr."""
    time_ns: int
    module: str
    stream: str
    line: str
    kind: ClassVar[str] = "module_log"


@dataclass(frozen=True)
class OtherEvent:
    """An event of a kind this tool version does not model (kept, never interpreted)."""
    kind: str
    time_ns: int
    body: tuple[tuple[str, JsonValue], ...] = ()

    def to_json(self) -> JsonObject:
        return dict(self.body)


Record = (RunStarted | RunStopping | RunStopped | RunEnd | ProcessExit | Violation | RunVerdict
          | UndeclaredKey | MutationRecord | FlagRecord | ModuleLogLine | PolicyApplicationsRecord | OtherEvent)

__all__ = ["FORMAT", "RECORD_TYPES", "FieldChange", "FlagRecord", "ModuleLogLine", "MutationRecord", "OtherEvent",
           "PolicyApplicationsRecord", "ProcessExit", "Record", "RunEnd", "RunStarted", "RunStopped", "RunStopping",
           "TaggedFieldChange", "UndeclaredKey", "RunVerdict", "Violation", "decode", "encode", "to_json_text"]


# Every modelled event type by its kind: decode looks a body's type up here (each has ``from_json(body, where=)``).
RECORD_TYPES: dict[str, Any] = {c.kind: c for c in (
    RunStarted, RunStopping, RunStopped, RunEnd, ProcessExit, Violation, RunVerdict, UndeclaredKey, MutationRecord,
    FlagRecord, ModuleLogLine, PolicyApplicationsRecord)}
# A damaged event of these kinds is an error, never an unknown event: a finding, the verdict or a mutation read
# as something else would make the log look cleaner than it is. (Their readers take absent fields as defaults.)
_NEVER_OTHER = frozenset({Violation.kind, RunVerdict.kind, MutationRecord.kind})


def encode(record: Record) -> JsonObject:
    """The JSON object of ``record`` as written to the log: ``kind``, ``time_ns``, then the type's own form."""
    return {"kind": record.kind, "time_ns": record.time_ns, **record.to_json()}


def to_json_text(record: Record) -> str:
    return json.dumps(encode(record), default=str)


def decode(body: Mapping[str, JsonValue], where: str = "the log") -> Record:
    """The record of a logged JSON object; an unknown kind (or a damaged event of a kind that may be kept
    as one) becomes an :class:`OtherEvent`."""
    if not isinstance(body, Mapping):
        raise InputError(f"{where}: an event is not a JSON object")
    read = JsonFields(body)
    version = read.integer("format", FORMAT)
    if version > FORMAT:
        raise InputError(f"{where}: events in record format {version}, this tool reads up to {FORMAT}; "
                         "read this log with a newer astaa-deft")
    kind = read.text("kind")
    time_ns = read.integer("time_ns")
    record_type = RECORD_TYPES.get(kind)
    if record_type is None:
        return _other(kind, time_ns, body)
    try:
        record: Record = record_type.from_json({**body, "time_ns": time_ns}, where=where)
    except RecordError:  # a required field missing or malformed: keep the event, do not guess it
        if kind in _NEVER_OTHER:
            raise
        return _other(kind, time_ns, body)
    return record


def _other(kind: str, time_ns: int, body: Mapping[str, JsonValue]) -> OtherEvent:
    return OtherEvent(kind, time_ns, tuple((k, v) for k, v in body.items() if k not in ("kind", "time_ns")))
