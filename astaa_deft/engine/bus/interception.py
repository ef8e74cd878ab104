"""Bridge between the star proxy and an interceptor (the ASTAA test case engine).

Contract:

* Channels the interceptor names (``Interceptor.channels``) get an
  intercepting :class:`~astaa_deft.engine.bus.proxy.Forwarder`; every other
  channel keeps the proxy's zero-copy path (``plain_forwarder``).
* Each message of an intercepted channel goes through the interceptor once,
  in arrival order: through the channel's *lane* (``Interceptor.lane``: no
  objects built per message) where the interceptor offers one, else through
  ``on_message`` put in the lane's terms. Deliveries due later wait in a heap
  that a tick thread releases every ``TICK_SECONDS``; ``stop`` flushes the
  interceptor and releases everything still held.
* For every delivery the recorder gets one row on the channel's
  ``intercepted_key`` — (time ns, delivered payload, original or None,
  delivered to anyone, event or None) — so delivery, original and event can
  never be mismatched. Rows go out in batches (``topology.pack_deliveries``)
  when the forwarder has nothing more waiting, or at ``BATCH_LIMIT``.
* Deliveries to consumers wait in an outbox until the end of the forwarder's
  burst and are put together.
* ``on_mutation`` (if given) gets each typed mutation event, ``on_delivered``
  (if set) each channel and payload delivered to someone; both are called
  with the bridge's lock held, from a forwarder or the tick thread: keep them
  quick, and do not call back into the bridge.

Thread safety: the interceptor sees one call at a time (one lock, taken
once per burst). ``start``/``stop`` are called from one thread.

Why the forwarder is shaped this way (bursts, one put per burst, the lane,
FIFOs rather than callbacks on Zenoh's thread) is measured in
docs/performance.md ("Interception", and "session" for this module's form).
"""

from __future__ import annotations

import heapq
import itertools
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Protocol, cast

import zenoh

from astaa_deft.engine.bus.proxy import BLOCK, REMOTE, Forwarder, LiveRoute, plain_forwarder
from astaa_deft.engine.bus.topology import intercepted_key, pack_deliveries
from astaa_deft.model.json import JsonObject
from astaa_deft.model.records import Mutation, MutationRow, Rewritten

TICK_SECONDS = 0.01
BATCH_LIMIT = 256  # deliveries per recorder message at most (a batch of small messages stays one Zenoh message)

# (encoding, attachment, timestamp) of the real message a delivery comes from: what its put carries.
SampleMeta = tuple[zenoh.Encoding | None, zenoh.ZBytes | None, zenoh.Timestamp | None]
NO_META: SampleMeta = (None, None, None)


class DeliveryLike(Protocol):
    """One delivery the interceptor asks for (``intercept.engine.Delivery``)."""

    @property
    def consumers(self) -> tuple[str, ...]: ...
    @property
    def payload(self) -> bytes: ...
    @property
    def at(self) -> float: ...  # seconds since the bridge's start
    @property
    def original(self) -> bytes | None: ...
    @property
    def event(self) -> Mutation | None: ...


class JsonForm(Protocol):
    """A record that writes its own JSON form."""

    def to_json(self) -> JsonObject: ...


class Interceptor(Protocol):
    """The interceptor the bridge and the session drive (``intercept.engine.Interceptor``)."""

    def channels(self) -> set[str]: ...
    def on_message(self, channel: str, consumers: tuple[str, ...], payload: bytes,
                   now: float) -> Sequence[DeliveryLike]: ...
    def on_tick(self, now: float) -> Sequence[DeliveryLike]: ...
    def flush(self, now: float) -> Sequence[DeliveryLike]: ...
    # on_message for one channel without objects, where it can: returns None (untouched, every consumer, now),
    # a Rewritten (payload and mutation row: rewritten, every consumer, now) or a list of deliveries.
    def lane(self, channel: str, consumers: tuple[str, ...]) -> Lane | None: ...
    def event(self, row: MutationRow) -> Mutation: ...  # the typed event of a lane's event values
    def applications(self, now: float) -> Sequence[JsonForm]: ...  # per policy: what it touched, and why not


# A lane: the channel's messages in, the common answers (None: untouched; Rewritten) or the deliveries out.
Lane = Callable[[bytes, float], "Rewritten | Sequence[DeliveryLike] | None"]


@dataclass(slots=True)
class _Pending:
    live: LiveRoute
    delivery: DeliveryLike
    sample_meta: SampleMeta  # of the real message it came from


# One recorder row: (time ns, delivered payload, original, delivered to anyone, event or its values).
Row = tuple[int, bytes, bytes | None, bool, object]


class _Channel:
    """An intercepted channel: its route, its consumers' publishers and the rows not yet sent to the recorder."""

    __slots__ = ("live", "name", "pubs", "rows", "record_pub")

    def __init__(self, live: LiveRoute, record_pub: zenoh.Publisher):
        self.live = live
        self.name = live.route.channel.name
        self.pubs = [pub for _consumer, pub in live.publishers]
        self.rows: list[Row] = []
        self.record_pub = record_pub


def _same(event: object) -> Mutation:
    """The typed event of a row that already holds one (rows made from deliveries)."""
    return cast(Mutation, event)


class InterceptionBridge:
    """Intercepting forwarders for the star proxy (see the module's contract)."""

    def __init__(self, session: zenoh.Session, interceptor: Interceptor, start_monotonic: float,
                 on_mutation: Callable[[Mutation], None] | None = None):
        self.session = session
        self.interceptor = interceptor
        self.t0 = start_monotonic
        self.on_mutation = on_mutation
        self.targets = interceptor.channels()
        self._lock = threading.Lock()  # the interceptor sees one call at a time
        self._heap: list[tuple[float, int, _Pending]] = []
        self._order = itertools.count()
        self._channels: dict[str, _Channel] = {}
        self._last_meta: dict[str, SampleMeta] = {}
        self._outbox: list[tuple[zenoh.Publisher, zenoh.ZBytes | bytes, SampleMeta]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._tick_loop, name="interception-ticks", daemon=True)
        self.mutations = 0
        # e.g. the online monitors' feed; called with the channel and the delivered payload
        self.on_delivered: Callable[[str, bytes], None] | None = None

    # -- wiring ------------------------------------------------------------
    def make_forwarder(self, live: LiveRoute) -> Forwarder:
        """The proxy's forwarder for ``live``: intercepting if the interceptor names its channel."""
        name = live.route.channel.name
        if name not in self.targets:
            return plain_forwarder(live)
        record_pub = self.session.declare_publisher(
            intercepted_key(live.route.channel.key), congestion_control=BLOCK, allowed_destination=REMOTE)
        channel = self._channels[name] = _Channel(live, record_pub)
        consumers = tuple(c for c, _ in live.publishers)
        offered = self.interceptor.lane(name, consumers) if consumers else None
        if offered is None:
            return self._lane_forwarder(channel, self._general_lane(name, consumers), _same)
        typed = self.interceptor.event

        def event_values(values: object) -> Mutation:
            return typed(cast(MutationRow, values))  # the interceptor's lane answers with a mutation's row

        return self._lane_forwarder(channel, offered, event_values)

    def _general_lane(self, name: str, consumers: tuple[str, ...]) -> Lane:
        """``on_message`` in the lane's terms, where the interceptor offers no lane.

        Its common case, one delivery now to every consumer, takes the
        forwarder's short way (None, or :class:`Rewritten` with the typed
        event); anything else goes back as the deliveries, for ``_dispatch``.
        """
        on_message, count = self.interceptor.on_message, len(consumers)

        def lane(payload: bytes, now: float) -> Rewritten | Sequence[DeliveryLike] | None:
            deliveries = on_message(name, consumers, payload, now)
            if count and len(deliveries) == 1:
                d = deliveries[0]
                if d.at <= now and len(d.consumers) == count:
                    if d.original is None and d.event is None:
                        return None
                    if d.original is not None and d.event is not None:
                        return Rewritten(d.payload, d.event)
            return deliveries

        return lane

    def _lane_forwarder(self, channel: _Channel, lane: Lane, typed: Callable[[object], Mutation]) -> Forwarder:
        """An intercepting forwarder: the lane's common answers handled here, anything else by ``_dispatch``.

        ``typed`` makes the typed event of a :class:`Rewritten` answer's event.
        """
        live, pubs, name = channel.live, channel.pubs, channel.name
        lock, dispatch, record, outbox = self._lock, self._dispatch, self._record, self._outbox
        t0, monotonic, time_ns, last_meta = self.t0, time.monotonic, time.time_ns, self._last_meta
        append_out, rewritten = outbox.append, Rewritten

        def forward_burst(samples: list[zenoh.Sample]) -> None:
            live.count += len(samples)
            with lock:  # once per burst: the tick thread waits at most one burst (BURST_LIMIT samples)
                meta: SampleMeta = NO_META
                for sample in samples:
                    zpayload = sample.payload
                    meta = (sample.encoding, sample.attachment, sample.timestamp)
                    payload = zpayload.to_bytes()
                    now = monotonic() - t0
                    done = lane(payload, now)
                    if done is None:  # untouched: the very same Zenoh payload, no copy
                        for pub in pubs:
                            append_out((pub, zpayload, meta))
                        record(channel, (time_ns(), payload, None, True, None), _same)
                    elif isinstance(done, rewritten):  # rewritten, for every consumer, now
                        for pub in pubs:
                            append_out((pub, done.payload, meta))
                        record(channel, (time_ns(), done.payload, payload, True, done.event), typed)
                    else:
                        dispatch(live, done, meta, now=now, sample=sample)
                last_meta[name] = meta  # what a tick's injected message on this channel goes out with
                self._deliver_outbox()  # one burst of puts: Zenoh's sending thread wakes once for it

        def forward(sample: zenoh.Sample) -> None:
            forward_burst([sample])

        return Forwarder(forward, burst=forward_burst, on_idle=self.idle)

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
        for channel in self._channels.values():
            if channel.rows:
                self._send_rows(channel)

    def _send_rows(self, channel: _Channel) -> None:
        channel.record_pub.put(pack_deliveries(channel.rows, self.interceptor.event))
        channel.rows.clear()

    def start(self) -> None:
        """Start the tick thread (delayed deliveries, injections, windows closing)."""
        self._thread.start()

    def stop(self) -> None:
        """Stop the ticks, flush the interceptor and release everything it still held; send every row."""
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
    def _dispatch(self, live: LiveRoute, deliveries: Sequence[DeliveryLike], meta: SampleMeta, *, now: float,
                  sample: zenoh.Sample | None) -> None:
        """Deliveries for one message: due ones now (``sample``: the message, for its very payload), others later."""
        for d in deliveries:
            if d.at > now:
                heapq.heappush(self._heap, (d.at, next(self._order), _Pending(live, d, meta)))
            else:
                self._put(live, d, meta, sample)

    def _dispatch_unbound(self, d: DeliveryLike, now: float, force: bool = False) -> None:
        """A delivery produced by a tick (injected, released): route it by its channel."""
        if d.event is None:
            return
        name = d.event.channel
        channel = self._channels.get(name)
        if channel is None:
            return
        meta = self._last_meta.get(name, NO_META)
        if d.at > now and not force:
            heapq.heappush(self._heap, (d.at, next(self._order), _Pending(channel.live, d, meta)))
        else:
            self._put(channel.live, d, meta, None)

    def _put(self, live: LiveRoute, d: DeliveryLike, meta: SampleMeta, sample: zenoh.Sample | None) -> None:
        """One delivery: into the outbox for its consumers, and its row for the recorder."""
        # The very same Zenoh payload when nothing changed: no copy on the common path.
        payload: zenoh.ZBytes | bytes = sample.payload if d.original is None and sample is not None else d.payload
        if len(d.consumers) == len(live.publishers):  # all of them: no filtering
            for _consumer, pub in live.publishers:
                self._outbox.append((pub, payload, meta))
        elif d.consumers:
            wanted = set(d.consumers)
            for consumer, pub in live.publishers:
                if consumer in wanted:
                    self._outbox.append((pub, payload, meta))
        channel = self._channels[live.route.channel.name]
        data = payload if isinstance(payload, bytes) else payload.to_bytes()
        if d.event is None:  # untouched (always to someone: a delivery to no one carries an event)
            self._record(channel, (time.time_ns(), data, None, True, None), _same)
        else:
            self._record(channel, (time.time_ns(), data, d.original, bool(d.consumers), d.event), _same)

    def _record(self, channel: _Channel, row: Row, typed: Callable[[object], Mutation]) -> None:
        """One delivery's recorder row (the rows sent at ``BATCH_LIMIT``), and the listeners told.

        ``row``: (time ns, delivered payload, original, delivered to anyone,
        event); event None: delivered untouched. ``typed`` makes the typed
        event of the row's event for ``on_mutation`` (called only when there is one).
        """
        rows = channel.rows
        rows.append(row)
        _, data, _, delivered, event = row
        if event is not None:
            self.mutations += 1
            if self.on_mutation is not None:
                self.on_mutation(typed(event))
        if len(rows) >= BATCH_LIMIT:
            self._send_rows(channel)
        if delivered and self.on_delivered is not None:
            self.on_delivered(channel.name, data)

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
