"""Bridge between the star proxy and an interceptor (the ASTAA test case engine).

Channels the test case can touch get an intercepting forwarder; every other
channel keeps the proxy's zero-copy path. For intercepted channels the proxy
tells the recorder, on the tool's own key, what it delivered, what the
original was and what it did — one entry per delivery, so the three records
can never be mismatched. Entries that pile up while the forwarder is busy go
out together in one message (see ``topology.pack_deliveries``); the batch is sent
as soon as the forwarder has nothing more waiting, so at ordinary rates each
delivery is recorded at once. Samples are handled in bursts (``proxy.run_bursts``),
in arrival order: a burst is one sample whenever the forwarder keeps up.
The forwarder goes through a lane: the interceptor's own for the channel
(``Interceptor.lane``: no objects built per message) where it offers one,
else ``on_message`` put in the lane's terms (``_general_lane``).

Why the forwarder is shaped this way (bursts, one put per burst, the
lane, FIFOs rather than callbacks on Zenoh's thread) and what each choice
bought is measured in docs/performance.md ("Interception").
"""

from __future__ import annotations

import heapq
import itertools
import threading
import time
from typing import Any, Protocol
from collections.abc import Callable

import zenoh

from astaa_deft.engine.bus.proxy import BLOCK, REMOTE, LiveRoute, plain_forwarder
from astaa_deft.engine.bus.topology import intercepted_key, pack_deliveries

TICK_SECONDS = 0.01
BATCH_LIMIT = 256  # deliveries per recorder message at most (a batch of 200 B messages stays under 64 KiB)
# Deliveries to consumers wait in an outbox until the end of the forwarder's burst (see
# proxy.run_bursts): Zenoh's sending thread then wakes once per burst and sends it in one write
# (woken per message, it cost as much CPU as the mutation itself). When the forwarder keeps up,
# a burst is one message: no added delay.


class Interceptor(Protocol):
    def channels(self) -> set[str]: ...
    def on_message(self, channel: str, consumers: tuple[str, ...], payload: bytes, now: float) -> list: ...
    def on_tick(self, now: float) -> list: ...
    def flush(self, now: float) -> list: ...
    # on_message for one channel without objects, where it can (see intercept.engine.Interceptor.lane)
    def lane(self, channel: str, consumers: tuple[str, ...]) -> Callable[[bytes, float], Any] | None: ...
    # the typed event from a lane's event values
    def event(self, values: tuple) -> Any: ...


class _Pending:
    __slots__ = ("live", "delivery", "sample_meta")

    def __init__(self, live: LiveRoute, delivery: Any, sample_meta: tuple):
        self.live = live
        self.delivery = delivery
        self.sample_meta = sample_meta  # (encoding, attachment, timestamp) of the real message it came from


class InterceptionBridge:
    def __init__(self, session: zenoh.Session, interceptor: Interceptor, start_monotonic: float,
                 on_mutation: Callable[[Any], None] | None = None):
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
        # per channel: deliveries not yet sent to the recorder, (time ns, payload, original, delivered, event)
        self._batches: dict[str, list[tuple[int, bytes, bytes | None, bool, Any]]] = {}
        self._outbox: list[tuple[zenoh.Publisher, Any, tuple]] = []  # (publisher, payload, meta) to put
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._tick_loop, name="interception-ticks", daemon=True)
        self.mutations = 0
        # e.g. the online monitors' feed; called with the channel and the delivered payload
        self.on_delivered: Callable[[str, bytes], None] | None = None

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
        rows: list[tuple[int, bytes, bytes | None, bool, Any]] = []
        self._batches[name] = rows
        lane = self.interceptor.lane(name, consumers) if consumers else None
        if lane is None:
            lane = self._general_lane(name, consumers)
        return self._lane_forwarder(live, lane, rows, self._record_pubs[name])

    def _general_lane(self, name: str, consumers: tuple[str, ...]) -> Callable[[bytes, float], Any]:
        """``on_message`` in the lane's terms (see ``Interceptor.lane``), where the interceptor offers no lane.

        Its common case, one delivery now to every consumer, takes the
        forwarder's short way (an event object in place of the lane's values);
        anything else goes back as the deliveries, for ``_dispatch``.
        """
        on_message, count = self.interceptor.on_message, len(consumers)

        def lane(payload: bytes, now: float) -> Any:
            deliveries = on_message(name, consumers, payload, now)
            if count and len(deliveries) == 1:
                d = deliveries[0]
                if d.at <= now and len(d.consumers) == count:
                    if d.original is None and d.event is None:
                        return None
                    if d.original is not None and d.event is not None:
                        return d.payload, d.event
            return deliveries

        return lane

    def _lane_forwarder(self, live: LiveRoute, lane: Callable[[bytes, float], Any],
                        rows: list[tuple[int, bytes, bytes | None, bool, Any]],
                        record_pub: zenoh.Publisher) -> Callable[[zenoh.Sample], None]:
        """An intercepting forwarder: through the lane, the common delivery handled here (what _put does)."""
        name = live.route.channel.name
        pubs = [pub for _consumer, pub in live.publishers]
        lock, dispatch, outbox, on_mutation, typed = (self._lock, self._dispatch, self._outbox, self.on_mutation,
                                                      self.interceptor.event)
        t0, monotonic, time_ns, last_meta = self.t0, time.monotonic, time.time_ns, self._last_meta
        append_row, append_out = rows.append, outbox.append

        def forward_burst(samples: list[zenoh.Sample]) -> None:
            live.count += len(samples)
            with lock:  # once per burst: the tick thread waits at most one burst (BURST_LIMIT samples)
                for sample in samples:
                    zpayload = sample.payload
                    meta = (sample.encoding, sample.attachment, sample.timestamp)
                    payload = zpayload.to_bytes()
                    now = monotonic() - t0
                    done = lane(payload, now)
                    if done is None:  # untouched: the very same Zenoh payload, no copy
                        for pub in pubs:
                            append_out((pub, zpayload, meta))
                        append_row((time_ns(), payload, None, True, None))
                        data = payload
                    elif type(done) is tuple:  # rewritten, for every consumer, now
                        data, event = done  # the lane's event values, or an event (the general lane)
                        for pub in pubs:
                            append_out((pub, data, meta))
                        self.mutations += 1
                        append_row((time_ns(), data, payload, True, event))
                        if on_mutation is not None:
                            on_mutation(typed(event) if type(event) is tuple else event)
                    else:
                        dispatch(live, done, meta, now, sample)
                        continue
                    if len(rows) >= BATCH_LIMIT:
                        record_pub.put(pack_deliveries(rows, typed))
                        rows.clear()
                    if self.on_delivered is not None:
                        self.on_delivered(name, data)
                last_meta[name] = meta  # what a tick's injected message on this channel goes out with
                self._deliver_outbox()  # one burst of puts: Zenoh's sending thread wakes once for it

        def forward(sample: zenoh.Sample) -> None:
            forward_burst([sample])

        forward.on_idle = self.idle  # type: ignore[attr-defined]  # see StarProxy
        forward.burst = forward_burst  # type: ignore[attr-defined]
        return forward

    def idle(self) -> None:
        """The forwarders have nothing waiting: deliver what is in the outbox, send the recorder its batches."""
        with self._lock:
            self._send()

    def _deliver_outbox(self) -> None:
        for pub, payload, (encoding, attachment, timestamp) in self._outbox:
            if attachment is None and timestamp is None:  # the usual case: fewer arguments for pyo3 to parse
                pub.put(payload, encoding=encoding)
            else:
                pub.put(payload, encoding=encoding, attachment=attachment, timestamp=timestamp)
        self._outbox.clear()

    def _send(self) -> None:
        self._deliver_outbox()
        for name, rows in self._batches.items():
            if rows:
                self._record_pubs[name].put(pack_deliveries(rows, self.interceptor.event))
                rows.clear()

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
            self._send()

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
        if d.event is None:
            return
        name: str = d.event.channel
        live = self._routes.get(name)
        if live is None:
            return
        meta = self._last_meta.get(name, (None, None, None))
        if d.at > now and not force:
            heapq.heappush(self._heap, (d.at, next(self._order), _Pending(live, d, meta)))
        else:
            self._put(live, d, meta, None)

    def _put(self, live: LiveRoute, d: Any, meta: tuple, sample: zenoh.Sample | None) -> None:
        # The very same Zenoh payload when nothing changed: no copy on the common path.
        payload = sample.payload if d.original is None and sample is not None else d.payload
        if len(d.consumers) == len(live.publishers):  # all of them: no filtering
            for _consumer, pub in live.publishers:
                self._outbox.append((pub, payload, meta))
        elif d.consumers:
            wanted = set(d.consumers)
            for consumer, pub in live.publishers:
                if consumer in wanted:
                    self._outbox.append((pub, payload, meta))
        name = live.route.channel.name
        data = payload if type(payload) is bytes else payload.to_bytes()
        event = d.event
        rows = self._batches[name]
        if event is not None:
            self.mutations += 1
            rows.append((time.time_ns(), data, d.original, bool(d.consumers), event))
            if self.on_mutation is not None:
                self.on_mutation(event)
        else:
            rows.append((time.time_ns(), data, None, True, None))
        if len(rows) >= BATCH_LIMIT:
            self._record_pubs[name].put(pack_deliveries(rows, self.interceptor.event))
            rows.clear()
        if d.consumers and self.on_delivered is not None:
            self.on_delivered(name, data)

    def _tick_loop(self) -> None:
        while not self._stop.wait(TICK_SECONDS):
            with self._lock:
                now = time.monotonic() - self.t0
                for d in self.interceptor.on_tick(now):
                    self._dispatch_unbound(d, now)
                while self._heap and self._heap[0][0] <= now:
                    _, _, pending = heapq.heappop(self._heap)
                    self._put(pending.live, pending.delivery, pending.sample_meta, None)
                self._send()
