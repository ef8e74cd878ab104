"""A zoo member's module: its step (the replay factory, ``Step``) and its own process on Zenoh (``main``).

Written into each generated stack beside its spec (the spec's factory is
``zoo_module:Step``, found next to the spec); third-party style: no
astaa-deft import. The process reads ``member.json`` (its behaviour) and
builds its step from the same args the spec gives the factory, so the
recorded outputs are what ``Step`` computes on the frames the process fed it.

The step's contract (docs/spec.md, `replay:`): ``step(frame)`` gets
``{channel: decoded message}`` — the trigger and each other input the module
had, an input not heard from yet **absent** (no key) — and returns the
message published or None. A cycle that publishes several messages
(outputs 'several') publishes them one per ``step`` call: the first call
computes the cycle and returns its first message, each following call
returns the next one (whatever frame it is given) until the cycle's are
out. Each output names, in ``debug.inputs``, the header.seq of each input
the cycle used (None: absent) — for evaluation; the generated spec ignores
``debug`` in comparisons and names no provenance.
"""

from __future__ import annotations

import json
import math
import os
import signal
import sys
import threading
import time
import traceback
from collections import deque
from collections.abc import Mapping
from typing import Any

READY_LINE = "zoo module ready"
WEIGHTS = (0.5, 0.3, 0.2)  # input i's weight in the step's mix (a different message of any input changes it)
ABSENT = (0.0625, -0.125)  # what an absent input contributes (and it is counted)


def burn(seconds: float) -> None:
    """Spend ``seconds`` of this thread's CPU time (the step's cost; the result never depends on it)."""
    end = time.thread_time() + seconds
    while time.thread_time() < end:
        pass


class Step:
    """The member's step: a pure function of (frame, its own state)."""

    def __init__(self, state: str = "none", outputs: str = "one", numerics: str = "stable",
                 cost_ms: str = "1-3", parts: str = "3", silent_every: str = "4", warm: str = "0.5",
                 trigger: str = "a", inputs: str = "a,b,c", defect: str = "none"):
        self.state, self.outputs, self.numerics = state, outputs, numerics
        lo, _, hi = cost_ms.partition("-")
        self.cost = (float(lo) * 1e-3, float(hi or lo) * 1e-3)
        self.parts, self.silent_every, self.warm = int(parts), int(silent_every), float(warm)
        self.trigger, self.inputs = trigger, tuple(inputs.split(","))
        # 'crash_on_nan': a NaN in an input's values raises (the process dies of it); 'nan_state': a non-finite
        # input goes into the state unchecked and the next cycle raises on it (the defect needs the state)
        self.defect = defect
        self.x = [0.0, 0.0]  # the warm start: the previous cycle's result
        self.steps = 0  # cycles computed (state 'counters')
        self.seen: dict[str, int] = {}  # per input: cycles that had it (state 'counters')
        self.pending: list[dict] = []  # the rest of a cycle's messages (outputs 'several')
        self._born = os.getpid()
        self._copied = False

    def __setstate__(self, state: dict) -> None:  # deepcopy and unpickling come through here
        self.__dict__.update(state)
        self._copied = True

    def step(self, frame: Mapping[str, Any]) -> dict | None:
        if self.pending:
            return self.pending.pop(0)
        messages = self.cycle(frame)
        if not messages:
            return None
        self.pending = messages[1:]
        return messages[0]

    def cycle(self, frame: Mapping[str, Any]) -> list[dict]:
        """One cycle on a frame: its messages, in publish order (none, one, or `parts`)."""
        trig = frame[self.trigger]
        seq = int(trig["header"]["seq"])
        burn(self.cost[0] + (self.cost[1] - self.cost[0]) * ((seq * 0.6180339887498949) % 1.0))
        if self.defect == "nan_state" and not all(math.isfinite(value) for value in self.x):
            # the state an earlier cycle left (a NaN or inf input went into it unchecked): this cycle dies of it
            raise ValueError("zoo seeded defect: a non-finite state from an earlier cycle")
        u, absent = [0.0, 0.0], 0
        for weight, name in zip(WEIGHTS, self.inputs, strict=True):
            message = frame.get(name)
            v = message["v"] if message is not None else ABSENT
            absent += message is None
            if self.defect == "crash_on_nan" and any(math.isnan(float(value)) for value in v):
                raise ValueError(f"zoo seeded defect: NaN in input {name}")
            u = [u[0] + weight * float(v[0]), u[1] + weight * float(v[1])]
        if self.state == "warm":
            x = [self.warm * self.x[i] + (1.0 - self.warm) * u[i] for i in range(2)]
        elif self.state == "counters":
            self.steps += 1
            for name in self.inputs:
                if name in frame:
                    self.seen[name] = self.seen.get(name, 0) + 1
            x = [u[0] + 1e-3 * self.steps, u[1] - 1e-3 * self.seen.get(self.inputs[-1], 0)]
        else:
            x = u
        if self.numerics == "noisy_fork" and (self._copied or os.getpid() != self._born):
            # A native library's result in another process (or a copied state): off by an ulp (< 1e-15 for
            # |x| < 2), the error carried on in the warm start.
            up = math.inf if os.getpid() % 2 or self._copied else -math.inf
            x = [math.nextafter(v, up) for v in x]
        self.x = x
        if self.outputs == "none_some" and seq % self.silent_every == 3:
            return []
        used = {name: (int(frame[name]["header"]["seq"]) if name in frame else None) for name in self.inputs}
        count = self.steps if self.state == "counters" else 0
        parts = self.parts if self.outputs == "several" else 1
        return [{"header": {"seq": seq * parts + k, "stamp": trig["header"]["stamp"]},
                 "x": [x[0] + 0.25 * k, x[1] - 0.25 * k], "count": count, "absent": absent, "part": k,
                 "debug": {"inputs": used}} for k in range(parts)]


# -- the module's own process ------------------------------------------------------------------


class Scheduler:
    """What the process does around its step: which triggers start a cycle, which messages it reads."""

    def __init__(self, member: Mapping[str, Any]):
        self.trigger_mode, self.reading = member["trigger"], member["reading"]
        self.depth = int(member["queue_depth"])
        self.inputs = ("a", "b", "c")
        self.lock = threading.Condition()
        self.latest: dict[str, dict] = {}
        self.buffers: dict[str, deque] = {name: deque(maxlen=64) for name in self.inputs}
        self.queue: deque[tuple[dict, dict | None]] = deque()
        self.busy = False

    def on_message(self, name: str, message: dict) -> None:
        with self.lock:
            self.latest[name] = message
            self.buffers[name].append(message)
            if name != "a" or self.trigger_mode == "timer":
                return
            item = (message, dict(self.latest) if self.reading == "latched" else None)
            if self.trigger_mode == "each":
                self.queue.append(item)
            elif self.trigger_mode == "oldest_queued":
                if len(self.queue) < self.depth:
                    self.queue.append(item)
            elif self.trigger_mode == "newest_idle":
                self.queue.clear()
                self.queue.append(item)
            elif self.trigger_mode == "drop_busy" and not self.busy and not self.queue:
                self.queue.append(item)
            self.lock.notify()

    def next_frame(self, stop: threading.Event, tick: float | None) -> dict | None:
        """The next cycle's frame (None: nothing to do yet); marks the module busy."""
        with self.lock:
            if self.trigger_mode == "timer":
                if "a" not in self.latest:
                    return None
                trig, latched = self.latest["a"], dict(self.latest)
            else:
                if not self.queue:
                    self.lock.wait(0.05)
                if not self.queue or stop.is_set():
                    return None
                trig, latched = self.queue.popleft()
            self.busy = True
            if self.reading == "latched" and latched is not None:
                return {**latched, "a": trig}
            if self.reading == "sync":
                return {"a": trig, **{name: self._nearest(name, float(trig["header"]["stamp"]))
                                      for name in self.inputs[1:] if self.buffers[name]}}
            return {**self.latest, "a": trig}

    def _nearest(self, name: str, stamp: float) -> dict:
        """The buffered message of ``name`` whose stamp is nearest ``stamp`` (a tie: the newer)."""
        return min(reversed(self.buffers[name]), key=lambda m: abs(float(m["header"]["stamp"]) - stamp))

    def done(self) -> None:
        with self.lock:
            self.busy = False


def main() -> int:
    import zenoh

    with open(sys.argv[1] if len(sys.argv) > 1 else "member.json") as f:
        described = json.load(f)
    member, keys = described["member"], described["keys"]
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    step = Step(**described["args"])
    scheduler = Scheduler(member)
    session = zenoh.open(zenoh.Config.from_env())
    pub = session.declare_publisher(keys["out"], congestion_control=zenoh.CongestionControl.BLOCK)

    def subscriber(name: str) -> Any:
        def on_sample(sample: Any) -> None:
            try:
                message = json.loads(sample.payload.to_bytes())
            except ValueError:
                return
            scheduler.on_message(name, message)
        return session.declare_subscriber(keys[name], on_sample)

    subscribers = [subscriber(name) for name in scheduler.inputs]
    print(READY_LINE, flush=True)
    period = 1.0 / float(member["timer_hz"])
    next_tick = time.monotonic() + period
    while not stop.is_set():
        if member["trigger"] == "timer":
            time.sleep(max(0.0, next_tick - time.monotonic()))
            now = time.monotonic()
            next_tick += period * max(1, math.ceil((now - next_tick) / period))  # ticks missed while busy: skipped
        frame = scheduler.next_frame(stop, None)
        if frame is None:
            continue
        try:
            message = step.step(frame)
            while message is not None:
                if member.get("frame_id"):  # the node's own field, added to what the step returns
                    message = {**message, "header": {**message["header"], "frame_id": member["frame_id"]}}
                pub.put(json.dumps(message))
                message = step.step(frame) if step.pending else None
        except Exception:  # a step that raises kills the module, as a node dies of an uncaught exception
            traceback.print_exc()
            sys.stderr.flush()
            os._exit(1)  # now: Zenoh's threads would keep a process whose main thread raised alive
        scheduler.done()
    del subscribers
    session.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
