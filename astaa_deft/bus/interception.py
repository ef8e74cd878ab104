"""Bridge between the star proxy and an interceptor (the ASTAA test case engine).

Channels the test case can touch get an intercepting forwarder; every other
channel keeps the proxy's zero-copy path. For intercepted channels the proxy
tells the recorder, in one message per delivery on the tool's own key, what
it delivered (the payload), and in the attachment what the original was and
what it did — one message, so the three records can never be mismatched.
"""

from __future__ import annotations

import heapq
import itertools
import threading
import time
from typing import Any, Callable, Protocol

import zenoh

from .proxy import BLOCK, REMOTE, LiveRoute, plain_forwarder
from .topology import intercept_record, intercepted_key

TICK_SECONDS = 0.01


class Interceptor(Protocol):
    def channels(self) -> set[str]: ...
    def on_message(self, channel: str, consumers: tuple[str, ...], payload: bytes, now: float) -> list: ...
    def on_tick(self, now: float) -> list: ...
    def flush(self, now: float) -> list: ...


class _Pending:
    __slots__ = ("live", "delivery", "sample_meta")

    def __init__(self, live: LiveRoute, delivery: Any, sample_meta: tuple):
        self.live = live
        self.delivery = delivery
        self.sample_meta = sample_meta  # (encoding, attachment, timestamp) of the real message it came from


class InterceptionBridge:
    def __init__(self, session: zenoh.Session, interceptor: Interceptor, start_monotonic: float,
                 on_mutation: Callable[[dict], None] = lambda event: None):
        self.session = session
        self.interceptor = interceptor
        self.t0 = start_monotonic
        self.on_mutation = on_mutation
        self.targets = interceptor.channels()
        self._lock = threading.Lock()  # the interceptor sees one call at a time
        self._heap: list[tuple[float, int, _Pending]] = []
        self._order = itertools.count()
        self._routes: dict[str, LiveRoute] = {}
        self._last_meta: dict[str, tuple] = {}
        self._record_pubs: dict[str, zenoh.Publisher] = {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._tick_loop, name="interception-ticks", daemon=True)
        self.mutations = 0
        self.on_delivered: Callable[[str, bytes], None] = lambda channel, payload: None  # e.g. online monitors

    # -- wiring ------------------------------------------------------------
    def make_forwarder(self, live: LiveRoute) -> Callable[[zenoh.Sample], None]:
        name = live.route.channel.name
        if name not in self.targets:
            return plain_forwarder(live)
        self._routes[name] = live
        key = live.route.channel.key
        self._record_pubs[name] = self.session.declare_publisher(
            intercepted_key(key), congestion_control=BLOCK, allowed_destination=REMOTE)
        consumers = tuple(c for c, _ in live.publishers)

        def forward(sample: zenoh.Sample) -> None:
            live.count += 1
            meta = (sample.encoding, sample.attachment, sample.timestamp)
            payload = sample.payload.to_bytes()
            with self._lock:
                self._last_meta[name] = meta
                now = time.monotonic() - self.t0
                deliveries = self.interceptor.on_message(name, consumers, payload, now)
                self._dispatch(live, deliveries, meta, now, sample)

        return forward

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=2.0)
        with self._lock:
            now = time.monotonic() - self.t0
            for d in self.interceptor.flush(now):
                self._dispatch_unbound(d, now, force=True)
            while self._heap:
                _, _, pending = heapq.heappop(self._heap)
                self._put(pending.live, pending.delivery, pending.sample_meta, None)

    # -- delivery ------------------------------------------------------------
    def _dispatch(self, live: LiveRoute, deliveries: list, meta: tuple, now: float,
                  sample: zenoh.Sample | None) -> None:
        for d in deliveries:
            if d.at > now:
                heapq.heappush(self._heap, (d.at, next(self._order), _Pending(live, d, meta)))
            else:
                self._put(live, d, meta, sample)

    def _dispatch_unbound(self, d: Any, now: float, force: bool = False) -> None:
        """A delivery produced by a tick (injected, released): route it by its channel."""
        name = d.event.channel if d.event is not None else None
        live = self._routes.get(name) if name else None
        if live is None:
            return
        meta = self._last_meta.get(name, (None, None, None))
        if d.at > now and not force:
            heapq.heappush(self._heap, (d.at, next(self._order), _Pending(live, d, meta)))
        else:
            self._put(live, d, meta, None)

    def _put(self, live: LiveRoute, d: Any, meta: tuple, sample: zenoh.Sample | None) -> None:
        encoding, attachment, timestamp = meta
        untouched = d.original is None and sample is not None
        # The very same Zenoh payload when nothing changed: no copy on the common path.
        payload = sample.payload if untouched else d.payload
        wanted = set(d.consumers)
        for consumer, pub in live.publishers:
            if consumer in wanted:
                pub.put(payload, encoding=encoding, attachment=attachment, timestamp=timestamp)
        record = None
        if d.event is not None:
            self.mutations += 1
            body = d.event.to_json()
            record = intercept_record(body, d.original, delivered=bool(d.consumers))
            self.on_mutation(body)
        name = live.route.channel.name
        self._record_pubs[name].put(payload, encoding=encoding, attachment=record)
        if d.consumers:
            self.on_delivered(name, payload if isinstance(payload, bytes) else payload.to_bytes())

    def _tick_loop(self) -> None:
        while not self._stop.wait(TICK_SECONDS):
            with self._lock:
                now = time.monotonic() - self.t0
                for d in self.interceptor.on_tick(now):
                    self._dispatch_unbound(d, now)
                while self._heap and self._heap[0][0] <= now:
                    _, _, pending = heapq.heappop(self._heap)
                    self._put(pending.live, pending.delivery, pending.sample_meta, None)
