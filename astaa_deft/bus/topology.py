"""Who talks to whom: module configs, forwarding routes and recorded keys.

Pure logic from the spec and the chosen mode; no Zenoh calls here.

Star mode: every module is a Zenoh client of the tool's router and lives in
its own namespace ``sut/<module>``; a producer's ``k`` reaches the bus as
``sut/<producer>/k`` and only the proxy's republish to ``sut/<consumer>/k``
reaches a consumer. Passive mode: modules are peers meshed directly with
each other (each connects to every module started before it), so the tool
is just one more subscriber, off the message path.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from ..spec.model import Channel, Spec
from . import zenoh_config as zc

STAR_PREFIX = "sut"
TOOL_PREFIX = "astaa-deft"
EVENTS_KEY = f"{TOOL_PREFIX}/events"
UNDECLARED_PREFIX = f"{TOOL_PREFIX}/undeclared"


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


def module_configs(spec: Spec, mode: str, tool_endpoint: str) -> dict[str, dict[str, Any]]:
    """The Zenoh config each module gets, by module name."""
    configs: dict[str, dict[str, Any]] = {}
    if mode == "star":
        for m in spec.modules:
            configs[m.name] = zc.config_dict(mode="client", connect=[tool_endpoint], namespace=module_namespace(m.name))
        return configs
    if mode == "passive":
        earlier: list[str] = [tool_endpoint]
        for m in spec.modules:
            own = zc.loopback_endpoint()
            configs[m.name] = zc.config_dict(mode="peer", listen=[own], connect=list(earlier))
            earlier.append(own)
        return configs
    raise ValueError(f"unknown mode {mode!r}")


def tool_config(mode: str, listen: list[str], connect: list[str] = ()) -> dict[str, Any]:
    """The tool's own session: a router in star mode (modules are its clients), else a peer."""
    return zc.config_dict(mode="router" if mode == "star" else "peer", listen=listen, connect=list(connect))


def recorded_keys(spec: Spec, mode: str) -> list[tuple[str, Channel]]:
    """(key expression to subscribe, channel) for every declared channel."""
    if mode == "star":
        return [(r.source, r.channel) for r in star_routes(spec)]
    return [(ch.key, ch) for ch in spec.channels]


def split_star_key(full_key: str) -> tuple[str, str] | None:
    """'sut/<module>/<key>' → (module, key); None for anything else."""
    parts = full_key.split("/", 2)
    if len(parts) < 3 or parts[0] != STAR_PREFIX:
        return None
    return parts[1], parts[2]
