"""Online monitoring during a run: the same MonitorSet as `check`, fed live.

Messages are stamped in Zenoh's callback (their Zenoh timestamp, else the
receive time) and queued; decoding and evaluation happen on a worker thread,
off the proxy's forwarding path, in the order ``order`` states (the one
offline checking uses), after a short reorder wait. Process exits and
module output lines wait in the same queue, at their times, so they take
their place among the messages as offline. The worker also ticks the
deadline monitors every TICK seconds. Nothing later than ``horizon(now)``
(the run's end cannot come before it) is judged yet, and nothing later than
the run's end (``end_at``) ever is: an end may be dated before the tool
noticed it.
"""

from __future__ import annotations

import heapq
import queue
import threading
import time
from collections.abc import Callable

import zenoh

from astaa_deft.io.codecs import get_codec
from astaa_deft.io.codecs.base import DecodeError
from astaa_deft.model.sut import Spec
from astaa_deft.engine.monitor.monitorset import MonitorSet
from astaa_deft.engine.monitor.order import REORDER_WINDOW_NS, channel_ranks, order_key, sample_time_ns
from astaa_deft.engine.monitor.verdict import RunVerdict
from astaa_deft.engine.monitor.violation import Violation

TICK_SECONDS = 0.05
# The stop path waits for the monitors to judge what is queued while they make progress, and gives up on
# them when they judged nothing for STALLED_SECONDS (a monitor stuck on one item) or after STOP_WAIT_SECONDS.
STALLED_SECONDS = 2.0
STOP_WAIT_SECONDS = 30.0
_STOP = object()
EXIT = "__exit__"  # queue items that are not messages
LINE = "__log__"


class OnlineMonitors:
    def __init__(self, spec: Spec, start_ns: int, on_violation: Callable[[Violation], None]):
        self.spec = spec
        self.start_ns = start_ns
        self.set = MonitorSet(spec, start_ns)
        self.on_violation = on_violation
        self.wanted = self.set.channels()
        self._codecs = {ch.name: get_codec(ch.encoding) for ch in spec.channels if ch.name in self.wanted}
        self._seq = {name: 0 for name in self.wanted}
        self._ranks = channel_ranks(spec)
        self._held: list = []  # heap of (order key, channel, time, payload, seq) waiting for their turn
        self._q: queue.SimpleQueue = queue.SimpleQueue()
        self._judged = 0  # items the worker took off the queue: its progress, for the stop path
        self._subs: list = []
        self.ended_ns: int | None = None  # the run's end: nothing is judged past it
        self.horizon: Callable[[int], int] | None = None  # now -> the latest time that may be judged yet
        self._horizon_ns = -(2**63)  # its last answer: it only grows, so it is asked again only once passed
        self._side = 0  # numbers exits and output lines in the queue
        self._thread = threading.Thread(target=self._work, name="monitors", daemon=True)
        self._thread.start()

    def subscribe(self, session: zenoh.Session, keys: list[tuple[str, str]]) -> None:
        """Watch (key expression, channel name) pairs the monitors need."""
        for key_expr, name in keys:
            if name in self.wanted:
                self._subs.append(session.declare_subscriber(key_expr, self._callback(name)))

    def _callback(self, name: str) -> Callable[[zenoh.Sample], None]:
        q = self._q

        def on_sample(sample: zenoh.Sample) -> None:
            q.put((name, sample_time_ns(sample.timestamp, time.time_ns()), sample.payload.to_bytes()))

        return on_sample

    def feed(self, channel: str, payload: bytes) -> None:
        """A message delivered by the proxy itself (an intercepted channel)."""
        if channel in self.wanted:
            self._q.put((channel, time.time_ns(), payload))

    def process_exit(self, module: str, returncode: int, signal: str | None, time_ns: int,
                     *, during_shutdown: bool, stderr_tail: str) -> None:
        self._q.put((EXIT, time_ns, (module, returncode, signal, during_shutdown, stderr_tail)))

    def wants_log_lines(self) -> bool:
        return self.set.wants_log_lines()

    def log_line(self, module: str, text: str, time_ns: int) -> None:
        """A line a module wrote on its output (read by the session from the module's output file)."""
        self._q.put((LINE, time_ns, (module, text)))

    def _work(self) -> None:
        next_tick = time.monotonic() + TICK_SECONDS
        while True:
            try:
                item = self._q.get(timeout=max(0.0, min(next_tick - time.monotonic(), TICK_SECONDS)))
            except queue.Empty:
                item = None
            self._judged += 1
            if item is _STOP:
                self._release(None)
                return
            found: list[Violation] = []
            if item is not None:
                name, t, body = item
                if name in (EXIT, LINE):  # before the messages of their time, as offline
                    self._side += 1
                    heapq.heappush(self._held, (order_key(t, -1, self._side), name, t, body))
                else:
                    self._seq[name] += 1  # per channel in arrival order, as the recorder numbers them
                    heapq.heappush(self._held, (order_key(t, self._ranks[name], self._seq[name]), name, t, body))
            found = found + self._release(self._now())
            if time.monotonic() >= next_tick:
                next_tick = time.monotonic() + TICK_SECONDS
                found = found + self.set.on_tick(self._now())
            for v in found:
                self.on_violation(v)

    def _release(self, up_to_ns: int | None) -> list[Violation]:
        """Judge what is held up to up_to_ns (all of it for None), in order; nothing past the run's end."""
        found: list[Violation] = []
        while self._held and (up_to_ns is None or self._held[0][0][0] <= up_to_ns):
            (_, _, seq), name, t, body = heapq.heappop(self._held)
            if self.ended_ns is not None and t > self.ended_ns:
                continue  # the shutdown after the end: `check` does not judge it either
            if name == EXIT:
                module, code, sig, shutdown, tail = body
                found.extend(self.set.on_process_exit(module, code, sig, t, during_shutdown=shutdown, stderr_tail=tail))
                continue
            if name == LINE:
                module, text = body
                found.extend(self.set.on_log_line(module, text, t))
                continue
            try:
                value = self._codecs[name].decode(body)
            except DecodeError:
                value = None
            found.extend(self.set.on_message(name, t, value, seq))
        if up_to_ns is None:
            for v in found:
                self.on_violation(v)
            return []
        return found

    def end_at(self, time_ns: int) -> None:
        """The run ended at ``time_ns``: the shutdown that follows is no longer judged by the clock."""
        self.ended_ns = time_ns

    def _now(self) -> int:
        """The time judged up to: the reorder window behind the clock, never past the horizon or the run's end."""
        clock = time.time_ns()
        now = clock - REORDER_WINDOW_NS
        if self.horizon is not None and now > self._horizon_ns:
            self._horizon_ns = self.horizon(clock)
            now = min(now, self._horizon_ns)
        return now if self.ended_ns is None else min(now, self.ended_ns)

    def finish(self, time_ns: int) -> RunVerdict | None:
        """Stop listening, judge what is queued and what only the end can decide; the run's verdict — None
        when the monitors stopped making progress on what was queued (``STALLED_SECONDS``, or
        ``STOP_WAIT_SECONDS`` in all): the run was not fully observed, so no verdict, and the stop path goes on
        rather than waiting for them."""
        if self.ended_ns is not None:
            time_ns = min(time_ns, self.ended_ns)
        for sub in self._subs:
            sub.undeclare()
        self._subs = []
        self._q.put(_STOP)
        give_up = time.monotonic() + STOP_WAIT_SECONDS
        progress, stalled_since = self._judged, time.monotonic()
        while self._thread.is_alive() and time.monotonic() < give_up:
            self._thread.join(timeout=0.1)
            if self._judged != progress:
                progress, stalled_since = self._judged, time.monotonic()
            elif time.monotonic() - stalled_since > STALLED_SECONDS:
                break
        if self._thread.is_alive():  # still inside a monitor (which holds the set's lock): judge nothing more
            return None
        for v in self.set.on_tick(time_ns) + self.set.finish(time_ns):
            self.on_violation(v)
        return self.set.verdict()
