"""Who talks to whom: module configs, forwarding routes and recorded keys.

Pure logic from the spec and the chosen mode; no Zenoh calls here.

Star mode: every module is a Zenoh client of the tool's router and lives in
its own namespace ``sut/<module>``; a producer's ``k`` reaches the bus as
``sut/<producer>/k`` and only the proxy's republish to ``sut/<consumer>/k``
reaches a consumer. Passive mode: modules are clients of a plain Zenoh router
running in a process of its own (the part zenohd plays in a deployment), and
the tool is just one more client subscriber, off the message path.

(A full peer-to-peer mesh was tried for passive mode and dropped: a peer's
link to another sometimes came up only on the 1 s connect retry, so a module
missed the first second of traffic.)
"""

from __future__ import annotations

import json
import marshal
import struct
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from operator import attrgetter
from typing import Any, TypeAlias

from astaa_deft.model.json import JsonObject
from astaa_deft.model.sut import Channel, Spec
from astaa_deft.engine.bus import zenoh_config as zc
from astaa_deft.model.records import Mutation, MutationRow, RunMode

STAR_PREFIX = "sut"
TOOL_PREFIX = "astaa-deft"
EVENTS_KEY = f"{TOOL_PREFIX}/events"
UNDECLARED_PREFIX = f"{TOOL_PREFIX}/undeclared"
INTERCEPTED_PREFIX = f"{TOOL_PREFIX}/intercepted"  # per delivery on an intercepted channel, for the recorder


def intercepted_key(key: str) -> str:
    return f"{INTERCEPTED_PREFIX}/{key}"


_RECORD_HEAD = struct.Struct("<BI??")  # event form, event length, delivered, original present
EVENT_FIELDS = "fields"  # a wire event's field changes: (path, old, new) triples
# How the event rides. MARSHAL: a tuple of the event's attributes as Python values
# (``marshal`` takes exact built-in types only, so what it cannot carry falls back
# to JSON); the recorder turns it into the event's JSON form, off the proxy's thread.
EVENT_MARSHAL, EVENT_JSON = 1, 2
_EVENT_ATTRS = ("testcase", "policy", "action", "channel", "consumers", "message_index", "time")


def intercept_record(event: Mutation | Mapping[str, object], original: bytes | None, delivered: bool) -> bytes:
    """What was done, whether anything was delivered, the original: one intercepted delivery for the recorder.

    ``event`` is a mutation (``model.records.Mutation``, read by its
    attributes) or, already in its JSON form, a dict. Binary framing rather than JSON: the original payload rides
    as raw bytes, and the event as ``marshal`` data, whose encoding costs a
    tenth of the event's JSON form (which the recorder builds, in its own process).
    """
    if not isinstance(event, Mutation):
        form, body = EVENT_JSON, json.dumps(event, default=str).encode()
    else:
        try:
            body = marshal.dumps(_event_wire(event), 4)  # its attribute tuple, as a batch row carries it
            form = EVENT_MARSHAL
        except ValueError:  # a value of a type marshal does not carry exactly: the JSON form, as written
            form, body = EVENT_JSON, json.dumps(event.to_json(), default=str).encode()
    head = _RECORD_HEAD.pack(form, len(body), delivered, original is not None)
    return head + body + (original or b"")


@dataclass(frozen=True)
class WireEvent:
    """A mutation event as the recorder receives it: either its attributes or already its JSON form."""

    form: int  # EVENT_MARSHAL or EVENT_JSON
    value: MutationRow | JsonObject  # the attribute tuple (see intercept_record) or the JSON object


def read_intercept_record(attachment: bytes) -> tuple[WireEvent, bytes | None, bool]:
    """(event, original, delivered) from ``intercept_record``'s bytes; ValueError if they are malformed."""
    try:
        form, size, delivered, has_original = _RECORD_HEAD.unpack_from(attachment)
        start = _RECORD_HEAD.size
        raw = attachment[start:start + size]
        if form == EVENT_MARSHAL:
            value = marshal.loads(raw)
            if not isinstance(value, tuple) or len(value) != len(_EVENT_ATTRS) + 2:
                raise ValueError("not an event tuple")
        elif form == EVENT_JSON:
            value = json.loads(raw)
            if not isinstance(value, dict):
                raise ValueError("the event is not a JSON object")
        else:
            raise ValueError(f"unknown event form {form}")
    except (struct.error, EOFError, TypeError, ValueError) as exc:
        raise ValueError(f"malformed interception record: {exc}") from None
    original = bytes(attachment[start + size:]) if has_original else None
    return WireEvent(form, value), original, delivered


def wire_event_parts(event: WireEvent) -> dict[str, object]:
    """The attributes of a marshalled event by name (``fields``: (path, old, new) triples)."""
    return dict(zip((*_EVENT_ATTRS, EVENT_FIELDS, "detail"), event.value, strict=True))


_event_attrs = attrgetter(*_EVENT_ATTRS)
_change_attrs = attrgetter("path", "old", "new")


def _event_wire(event: Any) -> Any:
    """An event as a batch row carries it: its attribute tuple (see ``intercept_record``), or its JSON form.

    A tuple is that attribute tuple already (the interception lane's event
    values). (One ``attrgetter`` call: docs/performance.md, "The recorder's rows".)
    """
    kind = type(event)
    if kind is tuple:
        return event
    if kind is dict:
        return json.dumps(event, default=str).encode()
    return (*_event_attrs(event), tuple(map(_change_attrs, event.fields)), event.detail)


# One intercepted delivery for ``pack_deliveries``: (time ns, payload, original, delivered, event), the
# event a ``Mutation``, its compact row (``MutationRow``) or its JSON form (a dict), or None.
DeliveryRow: TypeAlias = tuple[int, bytes, "bytes | None", bool, object]


def pack_deliveries(rows: Sequence[DeliveryRow], typed: Callable[[MutationRow], Mutation] | None = None) -> bytes:
    """Intercepted deliveries of one channel in one message: (time ns, payload, original, delivered, event) each.

    ``original`` and ``event`` are None for a message delivered untouched;
    ``event`` is a mutation event (or its JSON form, a dict), duck-typed as in
    ``intercept_record``, or its attribute tuple, which ``typed`` turns into
    the event where marshal cannot carry it. The whole batch is one ``marshal`` call
    (docs/performance.md, "The recorder's rows"); an event
    whose values marshal cannot carry exactly travels as its JSON text.
    Under load the proxy sends what piled up while it was busy in one Zenoh
    message (one put, one recorder callback); when it keeps up, a batch holds
    one delivery and goes out at once, so batching adds no delay.
    """
    wire = [(t, payload, original, delivered, None if event is None else _event_wire(event))
            for t, payload, original, delivered, event in rows]
    try:
        return marshal.dumps(wire, 4)
    except ValueError:  # some event holds a value of a type marshal does not carry exactly
        return marshal.dumps([(t, payload, original, delivered, _marshal_safe(event, row[4], typed))
                              for row, (t, payload, original, delivered, event) in zip(rows, wire, strict=True)], 4)


def _marshal_safe(wire_event: Any, event: Any, typed: Callable[[MutationRow], Mutation] | None) -> Any:
    try:
        marshal.dumps(wire_event, 4)
        return wire_event
    except ValueError:
        if type(event) is tuple:
            if typed is None:
                raise
            event = typed(event)
        return json.dumps(event.to_json(), default=str).encode()


def unpack_deliveries(data: bytes) -> list[tuple[int, bytes, bytes | None, bool, WireEvent | None]]:
    """The rows of ``pack_deliveries``' bytes, events as ``WireEvent``; ValueError if they are malformed."""
    try:
        rows = marshal.loads(data)
    except (EOFError, TypeError, ValueError) as exc:
        raise ValueError(f"malformed interception batch: {exc}") from None
    if type(rows) is not list:
        raise ValueError("malformed interception batch: not a list of deliveries")
    out: list[tuple[int, bytes, bytes | None, bool, WireEvent | None]] = []
    for row in rows:
        if type(row) is not tuple or len(row) != 5:
            raise ValueError("malformed interception batch: a delivery is not a 5-tuple")
        t, payload, original, delivered, event = row
        if type(t) is not int or type(payload) is not bytes or type(delivered) is not bool or \
                (original is not None and type(original) is not bytes):
            raise ValueError("malformed interception batch: a delivery's time, payload or original")
        wire: WireEvent | None = None
        if type(event) is tuple:
            if len(event) != len(_EVENT_ATTRS) + 2:
                raise ValueError("malformed interception batch: not an event tuple")
            wire = WireEvent(EVENT_MARSHAL, event)
        elif type(event) is bytes:
            try:
                body = json.loads(event)
            except ValueError as exc:
                raise ValueError(f"malformed interception batch: event JSON: {exc}") from None
            if not isinstance(body, dict):
                raise ValueError("malformed interception batch: an event's JSON is not an object")
            wire = WireEvent(EVENT_JSON, body)
        elif event is not None:
            raise ValueError("malformed interception batch: an event is neither a tuple nor JSON")
        out.append((t, payload, original, delivered, wire))
    return out


def module_namespace(module: str) -> str:
    return f"{STAR_PREFIX}/{module}"


@dataclass(frozen=True)
class Route:
    """One declared channel in star mode: where it arrives, where it goes."""

    channel: Channel
    source: str  # the full key the producer's message arrives on
    destinations: tuple[tuple[str, str], ...]  # (consumer module, full key)


def star_routes(spec: Spec) -> list[Route]:
    return [
        Route(
            channel=ch,
            source=f"{module_namespace(ch.producer)}/{ch.key}",
            destinations=tuple((c, f"{module_namespace(c)}/{ch.key}") for c in ch.consumers),
        )
        for ch in spec.channels
    ]


def module_configs(spec: Spec, mode: RunMode, bus_endpoint: str) -> dict[str, JsonObject]:
    """The Zenoh config each module gets, by module name: a client of the bus (ValueError: not a mode)."""
    mode = RunMode(mode)
    return {
        m.name: zc.config_dict(mode="client", connect=[bus_endpoint],
                               namespace=module_namespace(m.name) if mode == RunMode.STAR else None)
        for m in spec.modules
    }


def recorded_keys(spec: Spec, mode: str) -> list[tuple[str, Channel]]:
    """(key expression to subscribe, channel) for every declared channel: where it is delivered.

    In the star that is the proxy's copy for the channel's first consumer, so
    log times and the order across channels are those a consumer saw (DeFT
    reconstructs a consumer's frames from them); a channel nobody consumes is
    taken where its producer publishes it.
    """
    if mode == RunMode.STAR:
        return [(r.destinations[0][1] if r.destinations else r.source, r.channel) for r in star_routes(spec)]
    return [(ch.key, ch) for ch in spec.channels]


def observed_keys(spec: Spec, mode: str) -> list[tuple[str, Channel]]:
    """(key expression, channel) the tool's own session subscribes to: where producers publish.

    Not the proxy's copies: its publishers deliver to remote sessions only
    (so the catch-all never sees them), which keeps them from the tool too.
    """
    if mode == RunMode.STAR:
        return [(r.source, r.channel) for r in star_routes(spec)]
    return [(ch.key, ch) for ch in spec.channels]


def split_star_key(full_key: str) -> tuple[str, str] | None:
    """'sut/<module>/<key>' → (module, key); None for anything else."""
    parts = full_key.split("/", 2)
    if len(parts) < 3 or parts[0] != STAR_PREFIX:
        return None
    return parts[1], parts[2]


def _keys_meet(a: str, b: str) -> bool:
    """True if two key expressions (wildcards allowed) share a key."""
    import zenoh  # local: the rest of this module stays free of Zenoh

    return a == b or zenoh.KeyExpr(a).intersects(zenoh.KeyExpr(b))


def token_destinations(spec: Spec, module: str, key: str) -> tuple[str, ...]:
    """Modules that see `module`'s liveliness token on `key`.

    A token is wired like a publication: a channel on that key produced by
    `module` sends it to the channel's consumers; a key no channel declares
    reaches every other module (the catch-all); a declared key produced by
    another module reaches nobody. A token the spec's ``liveliness:`` section
    declares for `module` reaches its consumers (every other module when it
    lists none).
    """
    tokens = [t for t in spec.liveliness if t.producer == module and _keys_meet(t.key, key)]
    if tokens:
        others = tuple(m.name for m in spec.modules if m.name != module)
        return tuple(dict.fromkeys(c for t in tokens for c in (others if t.consumers is None else t.consumers)))
    declared = [ch for ch in spec.channels if _keys_meet(ch.key, key)]
    if not declared:
        return tuple(m.name for m in spec.modules if m.name != module)
    return tuple(dict.fromkeys(c for ch in declared if ch.producer == module for c in ch.consumers))


def query_servers(spec: Spec, caller: str, key: str) -> tuple[str, ...]:
    """Modules a query of `caller` on `key` is sent to.

    Request-reply is wired by the channel on the key: its producer is the
    server (the queryable), its consumers the callers allowed to ask; a key no
    channel declares reaches every other module (the catch-all).
    """
    declared = [ch for ch in spec.channels if _keys_meet(ch.key, key)]
    if not declared:
        return tuple(m.name for m in spec.modules if m.name != caller)
    return tuple(dict.fromkeys(ch.producer for ch in declared if caller in ch.consumers))


def rebase_star_key(full_key: str, module: str) -> str | None:
    """'sut/<a>/<key>' → 'sut/<module>/<key>'; None for a key outside the star."""
    parts = split_star_key(full_key)
    return None if parts is None else f"{module_namespace(module)}/{parts[1]}"
