"""Online monitoring during a run: the same MonitorSet as `check`, fed live.

Messages are stamped on receipt in Zenoh's callback and queued; decoding and
evaluation happen on a worker thread, off the proxy's forwarding path. The
worker also ticks the deadline monitors every TICK seconds.
"""

from __future__ import annotations

import queue
import threading
import time
from typing import Callable

import zenoh

from ..codecs import get_codec
from ..codecs.base import DecodeError
from ..spec.model import Spec
from .monitorset import MonitorSet
from .verdict import Verdict
from .violation import Violation

TICK_SECONDS = 0.05
_STOP = object()


class OnlineMonitors:
    def __init__(self, spec: Spec, start_ns: int, on_violation: Callable[[Violation], None]):
        self.spec = spec
        self.start_ns = start_ns
        self.set = MonitorSet(spec, start_ns)
        self.on_violation = on_violation
        self.wanted = self.set.channels()
        self._codecs = {ch.name: get_codec(ch.encoding) for ch in spec.channels if ch.name in self.wanted}
        self._seq = {name: 0 for name in self.wanted}
        self._q: "queue.SimpleQueue" = queue.SimpleQueue()
        self._subs: list = []
        self.ended_ns: int | None = None  # the run's end: deadlines are not judged past it
        self._thread = threading.Thread(target=self._work, name="monitors", daemon=True)
        self._thread.start()

    def subscribe(self, session: zenoh.Session, keys: list[tuple[str, str]]) -> None:
        """Watch (key expression, channel name) pairs the monitors need."""
        for key_expr, name in keys:
            if name in self.wanted:
                self._subs.append(session.declare_subscriber(key_expr, self._callback(name)))

    def _callback(self, name: str):
        q = self._q

        def on_sample(sample: zenoh.Sample) -> None:
            q.put((name, time.time_ns(), sample.payload.to_bytes()))

        return on_sample

    def feed(self, channel: str, payload: bytes) -> None:
        """A message delivered by the proxy itself (an intercepted channel)."""
        if channel in self.wanted:
            self._q.put((channel, time.time_ns(), payload))

    def process_exit(self, module: str, returncode: int, signal: str | None, time_ns: int,
                     during_shutdown: bool, stderr_tail: str) -> None:
        self._q.put(("__exit__", time_ns, (module, returncode, signal, during_shutdown, stderr_tail)))

    def _work(self) -> None:
        next_tick = time.monotonic() + TICK_SECONDS
        while True:
            try:
                item = self._q.get(timeout=max(0.0, next_tick - time.monotonic()))
            except queue.Empty:
                item = None
            if item is _STOP:
                return
            found: list[Violation] = []
            if item is not None:
                name, t, body = item
                if name == "__exit__":
                    module, code, sig, shutdown, tail = body
                    found = self.set.on_process_exit(module, code, sig, t, shutdown, tail)
                else:
                    self._seq[name] += 1
                    try:
                        value = self._codecs[name].decode(body)
                    except DecodeError:
                        value = None
                    found = self.set.on_message(name, t, value, self._seq[name])
            if time.monotonic() >= next_tick:
                next_tick = time.monotonic() + TICK_SECONDS
                found = found + self.set.on_tick(self._now())
            for v in found:
                self.on_violation(v)

    def end_at(self, time_ns: int) -> None:
        """The run ended at ``time_ns``: the shutdown that follows is no longer judged by the clock."""
        self.ended_ns = time_ns

    def _now(self) -> int:
        now = time.time_ns()
        return now if self.ended_ns is None else min(now, self.ended_ns)

    def finish(self, time_ns: int) -> Verdict:
        """Stop listening, judge what is queued and what only the end can decide; the run's verdict."""
        if self.ended_ns is not None:
            time_ns = min(time_ns, self.ended_ns)
        for sub in self._subs:
            sub.undeclare()
        self._subs = []
        self._q.put(_STOP)
        self._thread.join(timeout=30.0)
        for v in self.set.on_tick(time_ns) + self.set.finish(time_ns):
            self.on_violation(v)
        return self.set.verdict()
