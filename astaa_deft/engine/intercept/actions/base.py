"""The action interface, and what the engine hands to the proxy.

An action module defines everything about its action:

* an ``ActionConfig`` subclass: the action as written in a test case (frozen,
  comparable), read from and written back to its XML element, checked
  against the spec; its flags (``defers``, ``adds_delivery``,
  ``carries_fields``, ``fields_separable``, ``pins_copies``), read by the
  minimiser instead of lists of action names; and how it redoes one logged
  step on one message (``pinned``), for minimisation's restricted test cases;
* an ``ActionDetail`` subclass (``detail_type``): what the action did to one
  message beyond its field changes, as a typed record with one encoding to
  and from the event's ``detail``;
* an ``ActionRuntime`` subclass: its state during one run, created by
  ``ActionConfig.start``. The engine feeds it the messages its policy
  selected (``apply``), every real message on its channels
  (``after_message``), clock ticks (``on_tick``) and the end of the run
  (``flush``); each returns the ``Pending`` deliveries it releases.

An action module registers its ``ActionConfig`` on :data:`ACTIONS`
(``@ACTIONS.register_class``) and declares its element's XSD type
(``schema``), which the test case reader splices into
``policies/testcase.xsd``'s Action group: adding an action is adding one
module to ``astaa_deft.engine.intercept.actions`` (the registry imports every
module of the package on first use).
"""

from __future__ import annotations

import copy
import random
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping
from dataclasses import dataclass, fields, replace
from decimal import Decimal
from typing import TYPE_CHECKING, Any, ClassVar, TypeVar

from astaa_deft.io.codecs import Codec, DecodeError, EncodeError
from astaa_deft.model.json import FieldValue, JsonObject
from astaa_deft.model.records import FieldChange, Mutation
from astaa_deft.model.registry import Registry

if TYPE_CHECKING:
    from lxml import etree

    from astaa_deft.model.sut import Channel, Spec
    from astaa_deft.engine.intercept.dictionary import Dictionary
    from astaa_deft.engine.intercept.testcase import ActionChecker, Policy


# ---------------------------------------------------------------- what the proxy gets

BuiltT = TypeVar("BuiltT")
_new_object = object.__new__


def built(cls: type[BuiltT], **values: object) -> BuiltT:
    """An instance of the frozen dataclass ``cls`` from ALL its field values, without its ``__init__``.

    For the engine's per-message path (why: docs/performance.md, "records").
    The instance is the same as ``cls(**values)`` gives (equality, hash, repr,
    frozenness); tests/test_interception_records.py checks it. ``cls`` must
    not use ``__slots__``; every field must be given.
    """
    instance = _new_object(cls)
    instance.__dict__.update(values)
    return instance


@dataclass(frozen=True)
class Delivery:
    """Deliver ``payload`` to ``consumers`` at ``at`` (seconds since run start).

    ``original`` is the real payload this delivery was made from when it
    differs from it, is extra, or is a held-back real message delivered
    later (None: the message just received, untouched: forward it as is).
    ``consumers == ()`` carries only an event: what was dropped.
    """

    consumers: tuple[str, ...]
    payload: bytes
    at: float
    original: bytes | None = None
    event: Mutation | None = None


def combine_events(events: list[Mutation]) -> Mutation | None:
    """One event for a delivery that several policies acted on (they stack in document order).

    ``policy`` and ``action`` join the parts with '+', ``fields`` are
    concatenated, and ``detail.steps`` keeps each part's own detail.
    """
    if not events:
        return None
    if len(events) == 1:
        return events[0]
    first, last = events[0], events[-1]
    steps: list[FieldValue] = [{"policy": e.policy, "action": e.action, "detail": e.detail} for e in events]
    return Mutation(
        testcase=first.testcase, policy="+".join(e.policy for e in events),
        action="+".join(e.action for e in events), channel=first.channel, consumers=last.consumers,
        message_index=first.message_index, time=first.time,
        fields=tuple(change for e in events for change in e.fields), detail={"steps": steps})


# ---------------------------------------------------------------- in flight inside the engine

class Pending:
    """A delivery being built: the policies of a message act on these in turn.

    ``message`` holds the decoded message once an action changed fields
    (``payload`` is then stale until ``materialize``), so stacked ``set``
    policies decode and encode once in all.
    """

    __slots__ = ("consumers", "payload", "source", "at", "codec", "extra", "deferred", "events", "message")

    def __init__(self, consumers: tuple[str, ...], payload: bytes, at: float, codec: Codec, *,
                 source: bytes | None = None, extra: bool = False):
        self.consumers = consumers
        self.payload: bytes | None = payload
        self.source = payload if source is None else source  # the real payload it comes from
        self.at = at
        self.codec = codec
        self.extra = extra  # not the real message itself (a duplicate, an injection)
        # Held back (delay, reorder): it goes out with a later call, not as "the message
        # just received", so its delivery names its payload even when unchanged.
        self.deferred = False
        self.events: list[Mutation] = []
        self.message: dict | None = None

    def copy_for(self, consumers: tuple[str, ...], *, extra: bool | None = None) -> Pending:
        twin = Pending(consumers, self.payload, self.at, self.codec,  # type: ignore[arg-type]
                       source=self.source, extra=self.extra if extra is None else extra)
        twin.deferred = self.deferred
        twin.events = list(self.events)
        twin.message = copy.deepcopy(self.message)
        return twin

    def decode(self, codec: Codec) -> str | None:
        """Decode the payload into ``message`` unless an earlier action did; why it could not, else None.

        The field actions (``remove``, ``swap``, ``hold``) start with it: on an
        undecodable payload they record a skipped event and pass the message on."""
        if self.message is None:
            try:
                self.message = codec.decode(self.payload)  # type: ignore[arg-type]
            except DecodeError as exc:
                return f"undecodable: {exc}"
        return None

    def materialize(self) -> bytes:
        """The payload, encoding the changed message first if needed (EncodeError passes through)."""
        if self.message is not None:
            self.payload = self.codec.encode(self.message)
            self.message = None
        assert self.payload is not None
        return self.payload

    def to_delivery(self) -> Delivery:
        event = combine_events(self.events)
        if not self.consumers:  # dropped: only the event travels
            return built(Delivery, consumers=(), payload=self.source, at=self.at, original=self.source, event=event)
        try:
            payload = self.materialize()
        except EncodeError as exc:
            # Values are carries()-checked before they are set, so this is a last
            # resort: deliver the real payload and say why.
            self.message = None
            payload = self.payload = self.source
            if event is not None:
                event = replace(event, detail={**event.detail, "skipped": f"unencodable: {exc}"})
        untouched = not self.extra and not self.deferred and payload is self.source
        return built(Delivery, consumers=self.consumers, payload=payload, at=self.at,
                     original=None if untouched else self.source, event=event)


# ---------------------------------------------------------------- the interface

@dataclass
class MessageInfo:
    """The real message a runtime is acting on."""

    channel: str
    index: int  # 1-based, on its channel
    now: float
    codec: Codec
    previous_message: Callable[[], dict]  # the previous real message, decoded; raises NotApplicable


@dataclass(kw_only=True)
class PolicyContext:
    """What an action's runtime gets to work with during one run."""

    testcase: str  # its id
    where: str  # its file (or id), for error messages
    policy: Policy
    spec: Spec
    dictionary: Dictionary
    channels: tuple[Channel, ...]  # the channels the policy targets
    consumers: dict[str, tuple[str, ...]]  # per channel: the consumers the policy affects
    rng: random.Random  # the action's own randomness (selection has its own)
    # For actions that create messages (interleave): the policy's window as
    # (start, end) seconds since run start, None until its anchor message came;
    # and its selection applied to a slot (channel, time) instead of a real message.
    window_bounds: Callable[[], tuple[float, float] | None]
    select_slot: Callable[[str, float], bool]

    def event(self, action: str, info: MessageInfo, consumers: tuple[str, ...],
              fields: tuple[FieldChange, ...] = (), *, detail: Mapping[str, object] | None = None) -> Mutation:
        """The mutation an action made of ``info``'s message; ``detail``: its JSON form (``ActionDetail.to_json``)."""
        return built(Mutation, testcase=self.testcase, policy=self.policy.id, action=action,
                     channel=info.channel, consumers=consumers, message_index=info.index, time=info.now,
                     fields=fields, detail={} if detail is None else dict(detail))


DetailT = TypeVar("DetailT", bound="ActionDetail")


@dataclass(frozen=True)
class ActionDetail:
    """What one action did to one message, beyond its field changes (subclasses: frozen dataclasses).

    Its JSON form is the event's ``detail`` object: the fields that are not
    None, in declaration order, lists for tuples. Readers get it back with
    ``from_json``, which ignores keys it does not know (a stacked event's
    ``steps``, a ``skipped`` note added on delivery).
    """

    shown: ClassVar[tuple[str, ...]] = ()  # the fields a one-line description of a mutation shows

    def to_json(self) -> JsonObject:
        out: JsonObject = {}
        for f in fields(self):
            value = getattr(self, f.name)
            if value is not None:
                out[f.name] = list(value) if isinstance(value, tuple) else value
        return out

    @classmethod
    def from_json(cls: type[DetailT], data: Mapping[str, object]) -> DetailT:
        known = {f.name for f in fields(cls)}
        return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in data.items() if k in known})

    def describe(self) -> list[str]:
        """``key=value`` for the ``shown`` fields present, as their JSON form prints."""
        return [f"{k}={v}" for k, v in self.to_json().items() if k in self.shown]


@dataclass(frozen=True)
class NoDetail(ActionDetail):
    """An action that records nothing but its event (drop)."""


@dataclass(frozen=True)
class PinnedStep:
    """One logged step of a mutation, to be redone on the one message it hit (see ``ActionConfig.pinned``)."""

    detail: Mapping[str, object]  # the step's logged detail (JSON form, untagged)
    fields: tuple[FieldChange, ...]  # the field changes kept for this step (values as sent); () if none
    original: ActionConfig | None  # the logged test case's action of the same kind for this policy, if known


class ActionConfig(ABC):
    """An action as written in a test case. Subclasses are frozen dataclasses."""

    name: ClassVar[str]  # its XML element name
    # Its element's type in the test case schema: an anonymous ``<xs:complexType>`` (in the XSD
    # namespace, prefix ``xs``) that may use testcase.xsd's named types (Field, Milliseconds, Count…).
    schema: ClassVar[str]
    detail_type: ClassVar[type[ActionDetail]] = NoDetail

    # What a delivery this action took part in looks like in the log; the minimiser
    # reads these flags, never lists of action names.
    defers: ClassVar[bool] = False  # delivered later than the real message arrived (delay, reorder)
    adds_delivery: ClassVar[bool] = False  # its event rides on an extra delivery (duplicate, interleave)
    carries_fields: ClassVar[bool] = False  # sets message fields, logged as field changes (set, interleave)
    # Whether some of the delivery's field changes can be kept without the others
    # (False: the delivery is raw bytes or nothing, as after corrupt or drop).
    fields_separable: ClassVar[bool] = True
    # Its extra deliveries are plain copies of the real message: a restricted test case
    # makes the kept copies of one message with one action (``pin_copies``).
    pins_copies: ClassVar[bool] = False

    @classmethod
    @abstractmethod
    def from_xml(cls, element: etree._Element, checker: ActionChecker) -> ActionConfig:
        """Read the (schema-valid) element; report semantic problems through ``checker``."""

    @abstractmethod
    def write_xml(self, element: etree._Element) -> None:
        """Fill in the attributes and children of this action's (empty) element."""

    def field_paths(self) -> tuple[str, ...]:
        """The field paths this action sets (as written, wildcards kept); none for an action that sets none."""
        return ()

    def check(self, policy: Policy, channels: tuple[Channel, ...],  # noqa: B027 (a hook with a default)
              checker: ActionChecker) -> None:
        """Check against the spec and dictionary (``checker`` has both); default: nothing to check."""

    @abstractmethod
    def start(self, context: PolicyContext) -> ActionRuntime:
        """A fresh runtime for one run."""

    @classmethod
    def pinned(cls, step: PinnedStep) -> ActionConfig | None:
        """This action redoing ``step`` on the one message it hit, for a restricted test case.

        None: nothing left to redo (e.g. a set whose fields were all
        minimised away). The default is the original action as written,
        if known: right for an action whose outcome its config decides alone.
        """
        return step.original if isinstance(step.original, cls) else None

    @classmethod
    def pin_copies(cls, count: int) -> ActionConfig:
        """One action making ``count`` plain copies of a message (for ``pins_copies`` actions)."""
        raise NotImplementedError(f"'{cls.name}' does not make copies")


# Every action by its XML element name: each action module registers its config class
# (``@ACTIONS.register_class``); the engine, the test case reader and its schema, and the minimiser
# look actions up here.
ACTIONS: Registry[type[ActionConfig]] = Registry("action", "astaa_deft.engine.intercept.actions")


# A runtime's shortcut for one channel (``ActionRuntime.fast_path``), called as fast(payload):
# (the payload ``apply`` would send, its field changes as (path, old, new) triples), with an
# event of the policy's action and no detail; or None to take the general path for this message.
FastPath = Callable[[bytes], "tuple[bytes, tuple[tuple[str, Any, Any], ...]] | None"]


class ActionRuntime:
    """Base of action runtimes; every hook has a do-nothing default."""

    # False for actions that never rewrite the real message they are offered (interleave).
    acts_on_messages: ClassVar[bool] = True

    def fast_path(self, channel: str) -> FastPath | None:
        """A shortcut for messages of ``channel`` when this policy alone acts on it (and for all its consumers).

        The engine then calls it instead of ``apply`` (with no ``Pending``,
        ``MessageInfo`` or stacking, and no objects built: see ``FastPath``);
        what it returns must be exactly the delivery and event the general
        path would lead to, or None for the general path. Default: none.
        """
        return None

    def apply(self, item: Pending, info: MessageInfo) -> list[Pending]:
        """What becomes of ``item`` (already narrowed to the affected consumers)."""
        return [item]

    def after_message(self, info: MessageInfo, payload: bytes) -> list[Pending]:
        """Called after every real message on the policy's channels; may release held items."""
        return []

    def on_tick(self, now: float) -> list[Pending]:
        return []

    def flush(self, now: float) -> list[Pending]:
        return []


# The test case schema's type of an element listing field paths (``remove``, ``hold``): <field path="…"/>, one or more.
FIELD_PATHS_SCHEMA = """
      <xs:complexType>
        <xs:sequence>
          <xs:element name="field" maxOccurs="unbounded">
            <xs:complexType>
              <xs:attribute name="path" type="FieldPath" use="required"/>
            </xs:complexType>
          </xs:element>
        </xs:sequence>
      </xs:complexType>"""


def required(element: etree._Element, name: str) -> str:
    """A required attribute of a schema-valid element (the schema guarantees it is there)."""
    value = element.get(name)
    assert isinstance(value, str), f"<{element.tag!s}> lacks '{name}' after schema validation"
    return value


def decimal_text(value: float) -> str:
    """A number as an XML Schema decimal: positional (no exponent), shortest round-trip digits."""
    text = format(Decimal(repr(float(value))), "f")
    return text.removesuffix(".0")
