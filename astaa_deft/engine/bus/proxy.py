"""The star proxy: republish each producer's messages into each consumer's namespace.

This is the per-message hot path. A message with nothing to change is
forwarded as the very same payload, encoding, attachment and timestamp
objects (no copy, no decode), through one cached publisher per destination.
"""


from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import zenoh

from astaa_deft.model.sut import Spec
from astaa_deft.engine.bus.star_requests import StarLiveliness, StarQueries
from astaa_deft.engine.bus.topology import (
    STAR_PREFIX, UNDECLARED_PREFIX, Route, module_namespace, split_star_key, star_routes,
)

BLOCK = zenoh.CongestionControl.BLOCK
REMOTE = zenoh.Locality.REMOTE
FIFO_CAPACITY = 16384  # samples waiting per route; when full, Zenoh holds back the sender (no loss)
# The bound is in samples, not bytes: what a full FIFO costs in memory is in docs/performance.md ("session").
BURST_LIMIT = 128  # samples a forwarder with a burst handler takes out of its FIFO at a time (see run_bursts)
CATCH_ALL_POLL_SECONDS = 0.002  # how often the catch-all looks into its FIFO (see StarProxy._catch_all_forwarder)


class LiveRoute:
    """A declared channel being forwarded: its publishers and a counter."""

    __slots__ = ("route", "publishers", "count")

    def __init__(self, route: Route, publishers: list[tuple[str, zenoh.Publisher]]):
        self.route = route
        self.publishers = publishers  # (consumer module, publisher)
        self.count = 0


def _nothing() -> None:
    """The idle hook of a forwarder that keeps nothing back."""


@dataclass(frozen=True)
class Forwarder:
    """How the proxy hands one subscriber's samples on.

    * ``handle``: one sample at a time, on the route's own thread.
    * ``burst``: if set, the samples go here instead, in bursts of up to
      ``BURST_LIMIT`` (:func:`run_bursts`), in arrival order.
    * ``on_idle``: called (bursts only) whenever the subscriber's FIFO runs
      empty, and once more after the subscriber is undeclared: a forwarder
      that keeps deliveries back sends them then.
    * ``poll_seconds``: (bursts only) look into the FIFO this often rather
      than wait on it (see ``StarProxy._catch_all_forwarder``).

    The callables run on the route's thread only; a forwarder shared by
    several routes guards its own state.
    """

    handle: Callable[[zenoh.Sample], None]
    burst: Callable[[list[zenoh.Sample]], None] | None = None
    on_idle: Callable[[], None] = _nothing
    poll_seconds: float | None = None


def plain_forwarder(live: LiveRoute) -> Forwarder:
    """The untouched path: same payload, encoding, attachment and timestamp objects."""
    pubs = [pub for _consumer, pub in live.publishers]

    def forward(sample: zenoh.Sample) -> None:
        live.count += 1
        payload, encoding, attachment, timestamp = (
            sample.payload, sample.encoding, sample.attachment, sample.timestamp)
        for pub in pubs:
            pub.put(payload, encoding=encoding, attachment=attachment, timestamp=timestamp)

    return Forwarder(forward)


class SampleQueue(Protocol):
    """A subscriber's FIFO as ``run_bursts`` takes from it (a Zenoh ``FifoChannel`` handler)."""

    def try_recv(self) -> zenoh.Sample | None: ...
    def recv(self) -> zenoh.Sample: ...


def run_bursts(fifo: SampleQueue, handle_burst: Callable[[list[zenoh.Sample]], None],
               on_idle: Callable[[], None], poll: float | None = None) -> None:
    """Hand ``handle_burst`` what waits in ``fifo``, up to BURST_LIMIT samples at a time, in arrival order.

    Taking them out together, before handling any, frees FIFO slots in a
    burst rather than waking Zenoh's receiving thread once per message
    (docs/performance.md, "Taking samples in bursts"). When the FIFO is
    empty, ``on_idle`` is called, then this waits for the next sample — or,
    with ``poll``, sleeps that many seconds and looks again (a waiting
    thread takes the GIL for every sample, a polling one once per look).
    Returns when the subscriber is undeclared and drained, after handling
    every sample it took out. Runs on the caller's thread.
    """
    try_recv, recv = fifo.try_recv, fifo.recv
    while True:
        samples: list[zenoh.Sample] = []
        try:
            while len(samples) < BURST_LIMIT:
                sample = try_recv()  # ZError once the subscriber is undeclared and drained
                if sample is None:
                    break
                samples.append(sample)
            if not samples:
                on_idle()
                if poll is not None:
                    time.sleep(poll)
                    continue
                samples.append(recv())
        except zenoh.ZError:
            if samples:
                handle_burst(samples)
            raise
        handle_burst(samples)


class StarProxy:
    """Forward every declared channel, plus a catch-all for undeclared keys.

    Each declared channel has its own subscriber, whose samples queue in a
    Zenoh FIFO channel (native side) and are forwarded by a thread of its
    own, and so does the catch-all (why FIFOs rather than callbacks on
    Zenoh's threads: docs/performance.md, "session"). Order is kept per
    channel. ``make_forwarder`` is where a later stage
    (interception) substitutes its own :class:`Forwarder` for a route.
    ``start`` and ``stop`` are called from one thread; ``counts`` from any.
    """

    def __init__(self, session: zenoh.Session, spec: Spec,
                 on_undeclared: Callable[[str, str], None] = lambda module, key: None,
                 make_forwarder: Callable[[LiveRoute], Forwarder] = plain_forwarder):
        self.session = session
        self.spec = spec
        self.on_undeclared = on_undeclared
        self.make_forwarder = make_forwarder
        self.routes: dict[str, LiveRoute] = {}
        self._undeclared_pubs: dict[str, list[zenoh.Publisher]] = {}
        self._lock = threading.Lock()
        self._subscribers: list[zenoh.Subscriber] = []
        self._threads: list[threading.Thread] = []
        self.undeclared_count = 0
        # Liveliness tokens and queries are wired like publications (see star_requests).
        self.liveliness = StarLiveliness(session, spec, on_undeclared)
        self.queries = StarQueries(session, spec, on_undeclared)

    def start(self) -> None:
        for route in star_routes(self.spec):
            live = LiveRoute(route, [(consumer, self._publisher(key)) for consumer, key in route.destinations])
            self.routes[route.source] = live
            self._pump(route.source, self.make_forwarder(live), f"fwd-{route.channel.name}")
        # allowed_origin=REMOTE keeps our own republished copies out of the catch-all.
        self._pump(f"{STAR_PREFIX}/**", self._catch_all_forwarder(), "fwd-catch-all", allowed_origin=REMOTE)
        self.liveliness.start()
        self.queries.start()

    def _pump(self, key_expr: str, forwarder: Forwarder, name: str,
              allowed_origin: zenoh.Locality | None = None) -> None:
        queue = zenoh.handlers.FifoChannel(FIFO_CAPACITY)
        sub = (self.session.declare_subscriber(key_expr, queue) if allowed_origin is None
               else self.session.declare_subscriber(key_expr, queue, allowed_origin=allowed_origin))
        self._subscribers.append(sub)
        handle, burst, on_idle, poll = forwarder.handle, forwarder.burst, forwarder.on_idle, forwarder.poll_seconds
        fifo = sub.handler

        def run() -> None:
            try:
                if burst is None:
                    for sample in sub:  # ends when the subscriber is undeclared
                        handle(sample)
                    return
                run_bursts(fifo, burst, on_idle, poll)
            except zenoh.ZError:  # undeclared and drained: what the last samples left waiting goes out too
                with contextlib.suppress(zenoh.ZError):
                    on_idle()

        thread = threading.Thread(target=run, name=name, daemon=True)
        thread.start()
        self._threads.append(thread)

    def stop(self) -> None:
        self.queries.stop()
        self.liveliness.stop()
        for sub in self._subscribers:
            sub.undeclare()
        for thread in self._threads:
            thread.join(timeout=2.0)
        self._subscribers, self._threads = [], []

    def counts(self) -> dict[str, int]:
        return {live.route.channel.name: live.count for live in self.routes.values()}

    def _publisher(self, key: str) -> zenoh.Publisher:
        return self.session.declare_publisher(key, congestion_control=BLOCK, allowed_destination=REMOTE)

    def _catch_all_forwarder(self) -> Forwarder:
        """The catch-all sees every producer's message and forwards only undeclared keys.

        It looks into its FIFO every CATCH_ALL_POLL_SECONDS rather than
        waiting on it (``run_bursts`` with ``poll``): waiting, it woke for every message
        of every declared channel and took the GIL each time, which on a
        busy channel handed the GIL to and fro with that channel's
        forwarder (with ``set`` on every message, the forwarder's puts then
        waited for this thread). An undeclared key's messages wait up to
        that long more; declared channels, the traffic that matters, none.
        """
        routes = self.routes

        def burst(samples: list[zenoh.Sample]) -> None:
            for sample in samples:
                full_key = str(sample.key_expr)
                if full_key not in routes:  # declared: its own subscriber forwards it
                    self._forward_undeclared(sample, full_key)

        def forward(sample: zenoh.Sample) -> None:
            burst([sample])

        return Forwarder(forward, burst=burst, poll_seconds=CATCH_ALL_POLL_SECONDS)

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
