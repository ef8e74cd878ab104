"""The records of a run: what the interception did, how a module exited, what broke, the verdict's class.

One type per record kind, exchanged by the interception, the monitors, the
launcher, the recorder and the log:

* :class:`Verdict` — the CRASH scale (Kropp, Koopman & Siewiorek, FTCS 1998),
  worst first, with ``Pass`` last; its values are the text the log, the
  console and the campaign journal have always held;
* :class:`FieldChange` (the message's values) and :class:`TaggedFieldChange`
  (the same in their tagged JSON form, as a log holds it), and
  :class:`Mutation` — what one policy (or a stack of policies) did to one
  message; :data:`MutationRow` its compact tuple form;
* :class:`ProcessExit` — a module's exit, as the launcher sees it and the log
  stores it;
* :class:`Violation` — a broken invariant;
* :class:`RunEnd` — why the run ended.

Each type owns its one JSON form: ``to_json()`` writes it and ``from_json(obj,
where=...)`` reads it back, checking what it reads and raising
:class:`RecordError` (an ``InputError`` naming the place) for a damaged
record. The log adds a ``kind`` (and for some a ``time_ns``) around these
forms (``io.log.records``). All types are frozen, so they are safe to share
between threads.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import ClassVar, TypeAlias

from astaa_deft.model.errors import InputError, Problem
from astaa_deft.model.json import FieldValue, JsonObject, JsonValue
from astaa_deft.model.json_fields import JsonFields
from astaa_deft.model.tagged import from_tagged, to_tagged
from astaa_deft.model.vocabulary import TextEnum


class RecordError(InputError):
    """A record that is not what its kind says (a damaged log, journal or pipe message): exit code 2."""


def _damaged(where: str, what: str) -> RecordError:
    return RecordError(Problem(where, None, None, f"a damaged record: {what}",
                               "the file was cut or altered; record the run again"))


def _fields(body: object, where: str, kind: str) -> JsonFields:
    if not isinstance(body, Mapping):
        raise _damaged(where, f"a {kind} is not a JSON object")
    return JsonFields(body)


# ---------------------------------------------------------------- the verdict's class


class Verdict(TextEnum):
    """A run's class on the CRASH scale, worst first (see ``engine.monitor.verdict`` for how each is found).

    A ``str`` so that its text and JSON forms are its value ("Pass",
    "Silent", ...), byte for byte what logs and journals already hold.
    """

    CATASTROPHIC = "Catastrophic"  # the SUT as a whole is down
    RESTART = "Restart"  # a module hung or restarted
    ABORT = "Abort"  # a module exited abnormally
    SILENT = "Silent"  # an invariant broke and nothing in the system noticed
    HINDERING = "Hindering"  # a module reported an error that misstates what happened
    PASS = "Pass"  # none of the above

    @classmethod
    def named(cls, text: str) -> Verdict | None:
        """The class named ``text`` (any letter case), or None."""
        return next((v for v in cls if v.value.lower() == text.lower()), None)

    @property
    def rank(self) -> int:
        """0 for the worst class (Catastrophic) up to 5 for Pass."""
        return CRASH_SCALE.index(self)


class RunMode(TextEnum):
    """Where the tool sits on the bus during a run."""

    STAR = "star"  # in the middle: every module in its own namespace, every message republished by the proxy
    PASSIVE = "passive"  # an observer among the modules: adds nothing to their message path


CRASH_SCALE: tuple[Verdict, ...] = tuple(Verdict)  # worst first, Pass last
CRASH_CLASSES: tuple[Verdict, ...] = CRASH_SCALE[:-1]  # what a finding can point at (never Pass)


# ---------------------------------------------------------------- mutations


@dataclass(frozen=True)
class FieldChange:
    """One field a policy changed, with the message's own values: ``path`` is concrete (``points[2].v``).

    What the interception builds and the minimiser works with; a value may be
    NaN, bytes or a string JSON cannot hold, so its JSON form tags them
    (``model.tagged``). As a log holds it, the change is a
    :class:`TaggedFieldChange`.
    """

    path: str
    old: FieldValue = None
    new: FieldValue = None

    def to_json(self) -> JsonObject:
        """``{"path", "old", "new"}`` with the values tagged (strict JSON)."""
        return {"path": self.path, "old": to_tagged(self.old), "new": to_tagged(self.new)}

    def tagged(self) -> TaggedFieldChange:
        """The same change with its values in their tagged JSON form."""
        return TaggedFieldChange(self.path, to_tagged(self.old), to_tagged(self.new))


@dataclass(frozen=True)
class TaggedFieldChange:
    """One field change as a log holds it: its values in their tagged JSON form (``model.tagged``), as written."""

    path: str
    old: JsonValue = None
    new: JsonValue = None

    def to_json(self) -> JsonObject:
        """``{"path", "old", "new"}``, the values as held (already strict JSON)."""
        return {"path": self.path, "old": self.old, "new": self.new}

    @classmethod
    def from_json(cls, body: object, *, where: str = "the log") -> TaggedFieldChange:
        """The change of its JSON form (values stay tagged); RecordError if it is not an object."""
        obj = _fields(body, where, "field change")
        return cls(obj.text("path", "None"), obj.raw("old"), obj.raw("new"))

    def untagged(self) -> FieldChange:
        """The change with the message's own values (NaN, bytes… back from their tags)."""
        return FieldChange(self.path, from_tagged(self.old), from_tagged(self.new))


# The compact form of a mutation on the proxy's hot path and on the pipe to the recorder: the
# attributes of a Mutation in field order, field changes as (path, old, new) triples. A plain
# tuple because ``marshal`` (the proxy → recorder framing) carries exact built-in types only and
# building the dataclass and its changes per mutated message costs the proxy (docs/performance.md,
# "records"). Built only by ``mutation_row`` or ``Mutation.to_row``; read by ``Mutation.from_row``
# and ``Mutation.row_json``. Its detail is typed read-only (a Mapping, so that JSON details are field
# values too); what travels is the dict the action built.
MutationRow: TypeAlias = tuple[str, str, str, str, tuple[str, ...], int, float,
                               Sequence[tuple[str, FieldValue, FieldValue]], Mapping[str, FieldValue]]
# The first five attributes of a mutation (testcase, policy, action, channel, consumers): fixed for
# a policy on a channel, so the hot path builds a row from them and the three values per message.
MutationSource: TypeAlias = tuple[str, str, str, str, tuple[str, ...]]


class Rewritten:
    """A lane's answer "this payload, to every consumer, now", with its event.

    The interceptor's lane (``intercept.engine.Interceptor.lane``) answers a
    rewritten message with one, ``event`` its mutation's row; the proxy's
    general lane with the typed ``Mutation``; the forwarder knows which, by
    its lane, and puts ``event`` in the recorder's row as it is. A slotted
    class rather than a frozen dataclass: one is made per rewritten message,
    and a frozen dataclass's ``__init__`` costs several times more. Treat it
    as immutable.
    """

    __slots__ = ("payload", "event")

    def __init__(self, payload: bytes, event: MutationRow | Mutation):
        self.payload = payload
        self.event = event


def mutation_row(source: MutationSource, message_index: int, time: float,
                 changes: Sequence[tuple[str, FieldValue, FieldValue]], *,
                 detail: Mapping[str, FieldValue] | None = None) -> MutationRow:
    """The compact form of a mutation: ``source``'s attributes, the message's index and time, its changes.

    ``changes``: (path, old, new) triples; ``detail`` None: no detail (a new empty dict).
    """
    return source + (message_index, time, changes, {} if detail is None else detail)


@dataclass(frozen=True, kw_only=True)
class Mutation:
    """What one policy (or a stack of policies, names joined by '+') did to one message."""

    testcase: str
    policy: str
    action: str
    channel: str
    consumers: tuple[str, ...]
    message_index: int  # 1-based index of the real message on its channel
    time: float  # seconds since run start, when the real message arrived
    fields: tuple[FieldChange, ...] = ()
    detail: Mapping[str, FieldValue] = field(default_factory=dict)

    def to_row(self) -> MutationRow:
        """Its compact form (see :data:`MutationRow`)."""
        return mutation_row((self.testcase, self.policy, self.action, self.channel, self.consumers),
                            self.message_index, self.time, tuple([(c.path, c.old, c.new) for c in self.fields]),
                            detail=self.detail)

    @classmethod
    def from_row(cls, row: MutationRow) -> Mutation:
        """The mutation of its compact form."""
        testcase, policy, action, channel, consumers, index, time, changes, detail = row
        return cls(testcase=testcase, policy=policy, action=action, channel=channel, consumers=consumers,
                   message_index=index, time=time,
                   fields=tuple(FieldChange(path, old, new) for path, old, new in changes), detail=detail)

    def to_json(self) -> JsonObject:
        """Plain JSON types only; exceptional values are tagged (``model.tagged``)."""
        return Mutation.row_json(self.to_row())

    @staticmethod
    def row_json(row: MutationRow, tag: Callable[[FieldValue], JsonValue] = to_tagged) -> JsonObject:
        """The JSON form of a mutation from its compact form (the recorder's per-event path), without
        building the mutation: the one place that lays out a mutation's keys. ``tag`` writes a value
        (the log's record passes values already tagged through as they are)."""
        testcase, policy, action, channel, consumers, message_index, time, changes, detail = row
        return {
            "testcase": testcase, "policy": policy, "action": action, "channel": channel, "consumers": list(consumers),
            "message_index": message_index, "time": time,
            "fields": [{"path": path, "old": tag(old), "new": tag(new)} for path, old, new in changes],
            "detail": tag(detail),
        }


# ---------------------------------------------------------------- process exits


@dataclass(frozen=True, kw_only=True)
class ProcessExit:
    """A module's process exit: the launcher reports it, the monitors judge it, the log stores it."""

    kind: ClassVar[str] = "process_exit"

    module: str
    pid: int
    returncode: int
    signal: str | None  # e.g. "SIGKILL" when killed by a signal
    time_ns: int  # wall clock, ns since the epoch
    during_shutdown: bool  # the tool was stopping the run: an expected exit
    stderr_tail: str = ""

    @property
    def abnormal(self) -> bool:
        """An exit mid-run with a failing code or by a signal."""
        return not self.during_shutdown and (self.returncode != 0 or self.signal is not None)

    def describe(self, *, with_pid: bool = True) -> str:
        """"module 'planning' (pid 41) killed by SIGKILL" / "... exit code 3" (without the pid if asked)."""
        how = f"killed by {self.signal}" if self.signal else f"exit code {self.returncode}"
        pid = f" (pid {self.pid})" if with_pid else ""
        return f"module '{self.module}'{pid} {how}"

    def as_finding(self) -> str:
        """The sentence a finding about it says: "module 'planning' was killed by SIGKILL"."""
        how = f"was killed by {self.signal}" if self.signal else f"exited with code {self.returncode}"
        return f"module '{self.module}' {how}"

    def to_json(self) -> JsonObject:
        """The log's form (without ``kind``); ``abnormal`` is written for readers of the raw log."""
        return {"time_ns": self.time_ns, "module": self.module, "pid": self.pid, "returncode": self.returncode,
                "signal": self.signal, "during_shutdown": self.during_shutdown, "abnormal": self.abnormal,
                "stderr_tail": self.stderr_tail}

    @classmethod
    def from_json(cls, body: object, *, where: str = "the log") -> ProcessExit:
        """The exit of its JSON form; RecordError if a required field (module, pid, returncode) is missing."""
        obj = _fields(body, where, "process exit")
        module, pid, code = obj.optional_text("module"), obj.optional_integer("pid"), obj.optional_integer("returncode")
        if module is None or pid is None or code is None:
            raise _damaged(where, "a process exit without its module, pid or return code")
        return cls(module=module, pid=pid, returncode=code, signal=obj.optional_text("signal"),
                   time_ns=obj.integer("time_ns"), during_shutdown=obj.flag("during_shutdown"),
                   stderr_tail=obj.text("stderr_tail"))


# ---------------------------------------------------------------- violations


@dataclass(frozen=True, kw_only=True)
class Violation:
    """A broken invariant: when, where (channel and message, or module), and what the CRASH class points at."""

    kind: ClassVar[str] = "violation"  # the log event's kind

    invariant: str
    invariant_kind: str  # the invariant's kind (bound, deadline, process, ...)
    severity: str
    time_ns: int  # when the invariant broke (the message's time, or the deadline that expired)
    channel: str | None
    seq: int | None  # 1-based index of the message on its channel, as the recorder numbers it
    message: JsonObject | None  # the offending message (truncated, JSON-safe), or context for kinds without one
    detail: str
    crash: Verdict = Verdict.SILENT  # the CRASH class this violation points at
    module: str | None = None  # the module held responsible, when one is

    def to_json(self) -> JsonObject:
        """Its one JSON form: the log's ``violation`` event's body (without ``kind``), a verdict's ``first``,
        ``check --json`` — in the key order logs have always had."""
        return {
            "time_ns": self.time_ns, "invariant": self.invariant, "invariant_kind": self.invariant_kind,
            "severity": self.severity, "crash": self.crash, "detail": self.detail, "module": self.module,
            "channel": self.channel, "seq": self.seq, "message": self.message,
        }

    @classmethod
    def from_json(cls, body: object, *, where: str = "the log") -> Violation:
        """The violation of its JSON form; RecordError if it is not an object.

        Lenient as logs have always been read: an absent or malformed field
        takes its default (a time of 0, an unknown class Silent) rather than
        losing the finding.
        """
        obj = _fields(body, where, "violation")
        message = obj.object("message")
        return cls(
            invariant=obj.text("invariant", "?"), invariant_kind=obj.text("invariant_kind", "?"),
            severity=obj.text("severity", "high"), time_ns=obj.integer("time_ns"),
            channel=obj.optional_text("channel"), seq=obj.optional_integer("seq"),
            message=dict(message) if message is not None else None, detail=obj.text("detail"),
            crash=Verdict.named(obj.text("crash", Verdict.SILENT)) or Verdict.SILENT,
            module=obj.optional_text("module"),
        )

    @property
    def where(self) -> str:
        """'on 'trajectory' #12', 'module 'control'', or ''."""
        if self.channel is not None:
            return f"on '{self.channel}'" + (f" #{self.seq}" if self.seq is not None else "")
        if self.module is not None:
            return f"module '{self.module}'"
        return ""


# ---------------------------------------------------------------- the run's end


@dataclass(frozen=True)
class RunEnd:
    """Why the run ended ('time limit', 'module planning exited', 'signal SIGINT', ...)."""

    kind: ClassVar[str] = "run_end"

    time_ns: int
    reason: str

    def to_json(self) -> JsonObject:
        return {"time_ns": self.time_ns, "reason": self.reason}

    @classmethod
    def from_json(cls, body: object, *, where: str = "the log") -> RunEnd:
        """The end of its JSON form; RecordError if it has no reason."""
        obj = _fields(body, where, "run end")
        reason = obj.optional_text("reason")
        if reason is None:
            raise _damaged(where, "a run end without its reason")
        return cls(obj.integer("time_ns"), reason)


# ---------------------------------------------------------------- the run's verdict


@dataclass(frozen=True, kw_only=True)
class RunVerdict:
    """A run's verdict: its class, its earliest finding, a one-line summary, the reasons for the class.

    The monitors give it (``time_ns`` 0); the session logs it with the time
    it was given (the log's ``verdict`` event) — one type for both.
    """

    kind: ClassVar[str] = "verdict"

    klass: Verdict
    first: Violation | None
    summary: str
    reasons: tuple[str, ...] = ()  # one line per finding that shaped the class
    time_ns: int = 0  # when the verdict was logged (0: not logged)

    def to_json(self) -> JsonObject:
        """Its one JSON form: the ``verdict`` log event's body (without ``kind``), ``check --json``'s verdict."""
        return {"time_ns": self.time_ns, "class": self.klass, "first": self.first.to_json() if self.first else None,
                "summary": self.summary, "reasons": list(self.reasons)}

    @classmethod
    def from_json(cls, body: Mapping[str, JsonValue], *, where: str = "the log") -> RunVerdict:
        """The verdict of its JSON form (an unknown class reads as Silent, as a damaged finding's does);
        RecordError if ``first`` is damaged. A first finding without a time has the verdict's."""
        read = JsonFields(body)
        time_ns = read.integer("time_ns")
        first = read.raw("first")
        if first is not None and not isinstance(first, Mapping):
            raise _damaged(where, "a verdict whose first finding is not an object")
        return cls(klass=Verdict.named(read.text("class", "?")) or Verdict.SILENT,
                   first=Violation.from_json({"time_ns": time_ns, **first}, where=where) if first else None,
                   summary=read.text("summary"), reasons=read.texts("reasons"), time_ns=time_ns)
