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
import struct
from dataclasses import dataclass
from typing import Any

from ..spec.model import Channel, Spec
from . import zenoh_config as zc

STAR_PREFIX = "sut"
TOOL_PREFIX = "astaa-deft"
EVENTS_KEY = f"{TOOL_PREFIX}/events"
UNDECLARED_PREFIX = f"{TOOL_PREFIX}/undeclared"
INTERCEPTED_PREFIX = f"{TOOL_PREFIX}/intercepted"  # per delivery on an intercepted channel, for the recorder


def intercepted_key(key: str) -> str:
    return f"{INTERCEPTED_PREFIX}/{key}"


_RECORD_HEAD = struct.Struct("<I??")  # event JSON length, delivered, original present


def intercept_record(event: dict, original: bytes | None, delivered: bool) -> bytes:
    """The attachment of an intercepted delivery: what was done, whether anything was delivered, the original.

    Binary framing rather than JSON: the original payload rides as raw bytes
    (base64 inside JSON cost more than the mutation itself on the hot path).
    """
    event_json = json.dumps(event, default=str).encode()
    head = _RECORD_HEAD.pack(len(event_json), delivered, original is not None)
    return head + event_json + (original or b"")


def read_intercept_record(attachment: bytes) -> tuple[dict, bytes | None, bool]:
    size, delivered, has_original = _RECORD_HEAD.unpack_from(attachment)
    start = _RECORD_HEAD.size
    event = json.loads(attachment[start:start + size])
    original = bytes(attachment[start + size:]) if has_original else None
    return event, original, delivered


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


def module_configs(spec: Spec, mode: str, bus_endpoint: str) -> dict[str, dict[str, Any]]:
    """The Zenoh config each module gets, by module name: a client of the bus."""
    if mode not in ("star", "passive"):
        raise ValueError(f"unknown mode {mode!r}")
    return {
        m.name: zc.config_dict(mode="client", connect=[bus_endpoint],
                               namespace=module_namespace(m.name) if mode == "star" else None)
        for m in spec.modules
    }


def recorded_keys(spec: Spec, mode: str) -> list[tuple[str, Channel]]:
    """(key expression to subscribe, channel) for every declared channel: where it is delivered.

    In the star that is the proxy's copy for the channel's first consumer, so
    log times and the order across channels are those a consumer saw (DeFT
    reconstructs a consumer's frames from them); a channel nobody consumes is
    taken where its producer publishes it.
    """
    if mode == "star":
        return [(r.destinations[0][1] if r.destinations else r.source, r.channel) for r in star_routes(spec)]
    return [(ch.key, ch) for ch in spec.channels]


def observed_keys(spec: Spec, mode: str) -> list[tuple[str, Channel]]:
    """(key expression, channel) the tool's own session subscribes to: where producers publish.

    Not the proxy's copies: its publishers deliver to remote sessions only
    (so the catch-all never sees them), which keeps them from the tool too.
    """
    if mode == "star":
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
    another module reaches nobody.
    """
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
