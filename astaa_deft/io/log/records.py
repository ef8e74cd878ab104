"""Typed records of the run's event stream: one encoding to and from the log.

Every event the tool writes to ``/astaa/events`` (and shows on the console)
is one of the frozen dataclasses below; :func:`encode` turns a record into the
JSON object written to the log and :func:`decode` turns a logged object back
into a record. Readers work on records, never on the raw dicts, so a field's
name lives in one place.

The on-disk shape is the one earlier logs already have (a JSON object with a
``kind`` and a ``time_ns``), so existing logs stay readable. A record may carry
``"format": N``; a log written by a newer tool (``N`` > :data:`FORMAT`) is
refused with a clear message instead of being half understood.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, fields
from typing import Any, ClassVar
from collections.abc import Mapping

from astaa_deft.model.errors import InputError
from astaa_deft.model.json_fields import JsonFields
from astaa_deft.model.records import (
    FieldChange, Mutation, ProcessExit, RecordError, RunEnd, RunVerdict, Violation,
)
from astaa_deft.model.tagged import to_tagged

FORMAT = 1  # bump when a record's meaning changes; decode() refuses newer ones


@dataclass(frozen=True)
class RunStarted:
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
class RunStopping:
    """The run's end: the monitors' horizon (nothing after it is judged)."""
    time_ns: int
    kind: ClassVar[str] = "run_stopping"


@dataclass(frozen=True)
class RunStopped:
    time_ns: int
    kind: ClassVar[str] = "run_stopped"


@dataclass(frozen=True)
class UndeclaredKey:
    time_ns: int
    module: str
    key: str
    note: str = ""
    kind: ClassVar[str] = "undeclared_key"


@dataclass(frozen=True)
class MutationRecord:
    """A ``model.records.Mutation`` as the log holds it (``policy``/``action`` joined by '+' when stacked).

    The log adds the time and the sequence numbers of the original and the
    delivered message, and keeps the values of ``fields`` and ``detail`` in
    their tagged JSON form (``model.tagged``), as written. Logged on the
    mutations topic (without kind/time_ns) and handed to ``on_event`` live.
    """
    time_ns: int
    policy: str
    action: str
    channel: str
    message_index: int = 0  # 1-based index of the real message on its channel
    fields: tuple[FieldChange, ...] = ()
    testcase: str = ""
    consumers: tuple[str, ...] = ()
    time: float = 0.0  # seconds since the run's start, when the real message arrived
    detail: Any = None
    original_sequence: int | None = None
    delivered_sequence: int | None = None
    kind: ClassVar[str] = "mutation"

    @classmethod
    def of(cls, mutation: Mutation, time_ns: int) -> MutationRecord:
        """The record of a live mutation: its values in their tagged JSON form, as the log holds them."""
        return cls(time_ns, mutation.policy, mutation.action, mutation.channel, mutation.message_index,
                   tuple(FieldChange(c.path, to_tagged(c.old), to_tagged(c.new)) for c in mutation.fields),
                   mutation.testcase, mutation.consumers, mutation.time, to_tagged(mutation.detail))


@dataclass(frozen=True)
class PolicyApplicationsRecord:
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
    traffic: tuple[Any, ...] = ()  # per target channel: {channel, count, first_s, last_s}
    untouched_reason: str | None = None
    kind: ClassVar[str] = "policy_applications"


@dataclass(frozen=True)
class FlagRecord:
    """A payload the recorder could not decode (forwarded untouched; logged raw on the flags topic)."""
    time_ns: int
    channel: str
    sequence: int | None = None
    reason: str = ""
    size: int = 0
    kind: ClassVar[str] = "undecodable"


@dataclass(frozen=True)
class ModuleLogLine:
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
    body: tuple[tuple[str, Any], ...] = ()


Record = (RunStarted | RunStopping | RunStopped | RunEnd | ProcessExit | Violation | RunVerdict
          | UndeclaredKey | MutationRecord | FlagRecord | ModuleLogLine | PolicyApplicationsRecord | OtherEvent)

__all__ = ["FORMAT", "FieldChange", "FlagRecord", "ModuleLogLine", "MutationRecord", "OtherEvent",
           "PolicyApplicationsRecord", "ProcessExit", "Record", "RunEnd", "RunStarted", "RunStopped", "RunStopping",
           "UndeclaredKey", "RunVerdict", "Violation", "decode", "decode_mutation", "encode", "to_json_text"]

_SIMPLE = {c.kind: c for c in (RunStarted, RunStopping, RunStopped, UndeclaredKey, ModuleLogLine, FlagRecord,
                               PolicyApplicationsRecord)}
_MODEL: dict[str, type[ProcessExit] | type[RunEnd]] = {c.kind: c for c in (ProcessExit, RunEnd)}  # own their JSON


def encode(record: Record) -> dict:
    """The JSON object of ``record`` as written to the log."""
    if isinstance(record, OtherEvent):
        return {"kind": record.kind, "time_ns": record.time_ns, **dict(record.body)}
    if isinstance(record, RunVerdict):
        return {"kind": record.kind, **record.to_log_json()}
    if isinstance(record, MutationRecord):
        return {"kind": record.kind, "time_ns": record.time_ns, "testcase": record.testcase,
                "policy": record.policy, "action": record.action, "channel": record.channel,
                "consumers": list(record.consumers), "message_index": record.message_index, "time": record.time,
                "fields": [{"path": c.path, "old": c.old, "new": c.new} for c in record.fields],
                "detail": record.detail, "original_sequence": record.original_sequence,
                "delivered_sequence": record.delivered_sequence}
    if isinstance(record, Violation):
        return {"kind": record.kind, **record.to_log_json()}
    if isinstance(record, (ProcessExit, RunEnd)):
        return {"kind": record.kind, **record.to_json()}
    body: dict[str, Any] = {"kind": record.kind}
    for f in fields(record):
        value = getattr(record, f.name)
        body[f.name] = list(value) if isinstance(value, tuple) else value
    return body


def to_json_text(record: Record) -> str:
    return json.dumps(encode(record), default=str)


def decode(body: Mapping[str, Any], where: str = "the log") -> Record:
    """The record of a logged JSON object; an unknown kind becomes an :class:`OtherEvent`."""
    if not isinstance(body, Mapping):
        raise InputError(f"{where}: an event is not a JSON object")
    read = JsonFields(body)
    version = read.integer("format", FORMAT)
    if version > FORMAT:
        raise InputError(f"{where}: events in record format {version}, this tool reads up to {FORMAT}; "
                         "read this log with a newer astaa-deft")
    kind = read.text("kind")
    time_ns = read.integer("time_ns")
    if kind == RunVerdict.kind:
        return RunVerdict.from_json(body, where=where)
    if kind == MutationRecord.kind:
        return decode_mutation(body, time_ns)
    if kind == Violation.kind:
        return Violation.from_json(body, where=where)
    model = _MODEL.get(kind)
    if model is not None:
        try:
            return model.from_json({**body, "time_ns": time_ns}, where=where)
        except RecordError:  # a required field missing or malformed: keep the event, do not guess it
            return _other(kind, time_ns, body)
    cls = _SIMPLE.get(kind)
    if cls is None:
        return _other(kind, time_ns, body)
    values: dict[str, Any] = {}  # checked by the dataclass itself: a missing field is a TypeError below
    for f in fields(cls):
        if f.name in body:
            value = body[f.name]
            values[f.name] = tuple(value) if isinstance(value, list) else value
    values["time_ns"] = time_ns
    try:
        return cls(**values)
    except TypeError:  # a required field missing: keep the event, do not guess it
        return _other(kind, time_ns, body)


def _other(kind: str, time_ns: int, body: Mapping[str, Any]) -> OtherEvent:
    return OtherEvent(kind, time_ns, tuple((k, v) for k, v in body.items() if k not in ("kind", "time_ns")))


def decode_mutation(body: Mapping[str, Any], time_ns: int = 0) -> MutationRecord:
    """A mutation as the interception and the recorder write it (the mutations topic has no 'kind')."""
    read = JsonFields(body)
    return MutationRecord(time_ns or read.integer("time_ns"), read.text("policy"), read.text("action"),
                          read.text("channel"), read.integer("message_index"),
                          tuple(FieldChange.from_json(c) for c in read.objects("fields")), read.text("testcase"),
                          read.texts("consumers"), read.number("time"), read.raw("detail"),
                          read.optional_integer("original_sequence"), read.optional_integer("delivered_sequence"))
