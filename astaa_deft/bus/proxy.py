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
from .topology import STAR_PREFIX, UNDECLARED_PREFIX, Route, module_namespace, split_star_key, star_routes

BLOCK = zenoh.CongestionControl.BLOCK
REMOTE = zenoh.Locality.REMOTE


class LiveRoute:
    """A declared channel being forwarded: its publishers and a counter."""

    __slots__ = ("route", "publishers", "count")

    def __init__(self, route: Route, publishers: list[tuple[str, zenoh.Publisher]]):
        self.route = route
        self.publishers = publishers  # (consumer module, publisher)
        self.count = 0


def plain_forwarder(live: LiveRoute) -> Callable[[zenoh.Sample], None]:
    """The untouched path: same payload, encoding, attachment and timestamp objects."""
    pubs = [pub for _consumer, pub in live.publishers]

    def forward(sample: zenoh.Sample) -> None:
        live.count += 1
        payload, encoding, attachment, timestamp = (
            sample.payload, sample.encoding, sample.attachment, sample.timestamp)
        for pub in pubs:
            pub.put(payload, encoding=encoding, attachment=attachment, timestamp=timestamp)

    return forward


class StarProxy:
    """Forward every declared channel, plus a catch-all for undeclared keys.

    Each declared channel gets its own subscriber whose callback closes over
    its publishers (measured: ~25 % less CPU per message than one wildcard
    subscriber dispatching on the key). `make_forwarder` is where a later
    stage (interception) substitutes its own callback for a route.
    """

    def __init__(self, session: zenoh.Session, spec: Spec,
                 on_undeclared: Callable[[str, str], None] = lambda module, key: None,
                 make_forwarder: Callable[[LiveRoute], Callable[[zenoh.Sample], None]] = plain_forwarder):
        self.session = session
        self.spec = spec
        self.on_undeclared = on_undeclared
        self.make_forwarder = make_forwarder
        self.routes: dict[str, LiveRoute] = {}
        self._undeclared_pubs: dict[str, list[zenoh.Publisher]] = {}
        self._lock = threading.Lock()
        self._subscribers: list[zenoh.Subscriber] = []
        self.undeclared_count = 0

    def start(self) -> None:
        for route in star_routes(self.spec):
            live = LiveRoute(route, [(consumer, self._publisher(key)) for consumer, key in route.destinations])
            self.routes[route.source] = live
            self._subscribers.append(self.session.declare_subscriber(route.source, self.make_forwarder(live)))
        # allowed_origin=REMOTE keeps our own republished copies out of the catch-all.
        self._subscribers.append(self.session.declare_subscriber(
            f"{STAR_PREFIX}/**", self._catch_all, allowed_origin=REMOTE))

    def stop(self) -> None:
        for sub in self._subscribers:
            sub.undeclare()
        self._subscribers = []

    def counts(self) -> dict[str, int]:
        return {live.route.channel.name: live.count for live in self.routes.values()}

    def _publisher(self, key: str) -> zenoh.Publisher:
        return self.session.declare_publisher(key, congestion_control=BLOCK, allowed_destination=REMOTE)

    def _catch_all(self, sample: zenoh.Sample) -> None:
        full_key = str(sample.key_expr)
        if full_key in self.routes:  # declared: its own subscriber forwards it
            return
        self._forward_undeclared(sample, full_key)

    # -- catch-all ---------------------------------------------------------
    def _forward_undeclared(self, sample: zenoh.Sample, full_key: str) -> None:
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
