"""The star proxy: republish each producer's messages into each consumer's namespace.

This is the per-message hot path. A message with nothing to change is
forwarded as the very same payload, encoding, attachment and timestamp
objects (no copy, no decode), through one cached publisher per destination.
"""

from __future__ import annotations

import threading
from typing import Callable

import zenoh

from ..spec.model import Spec
from .topology import UNDECLARED_PREFIX, Route, STAR_PREFIX, module_namespace, split_star_key, star_routes

BLOCK = zenoh.CongestionControl.BLOCK
REMOTE = zenoh.Locality.REMOTE


class _LiveRoute:
    __slots__ = ("route", "publishers", "count")

    def __init__(self, route: Route, publishers: list[tuple[str, zenoh.Publisher]]):
        self.route = route
        self.publishers = publishers  # (consumer module, publisher)
        self.count = 0


class StarProxy:
    """Forward every declared channel, plus a catch-all for undeclared keys.

    `deliver` may be replaced by an interceptor (a later stage): it gets the
    sample and the route and does the puts itself.
    """

    def __init__(self, session: zenoh.Session, spec: Spec,
                 on_undeclared: Callable[[str, str], None] = lambda module, key: None):
        self.session = session
        self.spec = spec
        self.on_undeclared = on_undeclared
        self._routes: dict[str, _LiveRoute] = {}
        self._undeclared_seen: set[str] = set()
        self._undeclared_pubs: dict[str, list[zenoh.Publisher]] = {}
        self._lock = threading.Lock()
        self._subscriber: zenoh.Subscriber | None = None
        self.undeclared_count = 0

    def start(self) -> None:
        for route in star_routes(self.spec):
            pubs = [(consumer, self._publisher(key)) for consumer, key in route.destinations]
            self._routes[route.source] = _LiveRoute(route, pubs)
        # One subscription for the whole star: a dict lookup dispatches, and
        # allowed_origin=REMOTE keeps our own republished copies out.
        self._subscriber = self.session.declare_subscriber(
            f"{STAR_PREFIX}/**", self._on_sample, allowed_origin=REMOTE
        )

    def stop(self) -> None:
        if self._subscriber is not None:
            self._subscriber.undeclare()
            self._subscriber = None

    def counts(self) -> dict[str, int]:
        return {live.route.channel.name: live.count for live in self._routes.values()}

    def _publisher(self, key: str) -> zenoh.Publisher:
        return self.session.declare_publisher(key, congestion_control=BLOCK, allowed_destination=REMOTE)

    # -- hot path ----------------------------------------------------------
    def _on_sample(self, sample: zenoh.Sample) -> None:
        live = self._routes.get(str(sample.key_expr))
        if live is None:
            self._forward_undeclared(sample)
            return
        live.count += 1
        self.deliver(sample, live)

    def deliver(self, sample: zenoh.Sample, live: _LiveRoute) -> None:
        payload, encoding, attachment, timestamp = sample.payload, sample.encoding, sample.attachment, sample.timestamp
        for _consumer, pub in live.publishers:
            pub.put(payload, encoding=encoding, attachment=attachment, timestamp=timestamp)

    # -- catch-all ---------------------------------------------------------
    def _forward_undeclared(self, sample: zenoh.Sample) -> None:
        full_key = str(sample.key_expr)
        parts = split_star_key(full_key)
        if parts is None:
            return
        module, key = parts
        with self._lock:
            pubs = self._undeclared_pubs.get(full_key)
            if pubs is None:
                # Nobody declared who consumes it: every other module may.
                pubs = [self._publisher(f"{module_namespace(m.name)}/{key}")
                        for m in self.spec.modules if m.name != module]
                pubs.append(self._publisher(f"{UNDECLARED_PREFIX}/{key}"))
                self._undeclared_pubs[full_key] = pubs
                first = True
            else:
                first = False
        self.undeclared_count += 1
        for pub in pubs:
            pub.put(sample.payload, encoding=sample.encoding, attachment=sample.attachment, timestamp=sample.timestamp)
        if first:
            self.on_undeclared(module, key)
