"""A zoo member's inputs: channels a (the trigger), b and c on Zenoh, for the member's bus time, then exit 0.

Third-party style (no astaa-deft import; the session from ``ZENOH_CONFIG``).
Each message is ``{"header": {"seq", "stamp"}, "v": [two floats]}``: ``v``
is a function of (channel, seq), the stamp the wall time the message was
made. Channel c follows the member's readiness: from the start, only after
``c_start`` s, published ``c_lag`` s after its stamp ('late'), or at 1 Hz.
"""

from __future__ import annotations

import heapq
import json
import math
import signal
import sys
import threading
import time
from typing import Any

PHASE = {"a": 0.0, "b": 0.013}  # s: b is not in step with a


def value(name: str, seq: int) -> list[float]:
    k = "abc".index(name) + 1
    return [math.sin(seq * 1.3 + k), math.cos(seq * 0.7 + 2.0 * k)]


def main() -> int:
    import zenoh

    with open(sys.argv[1] if len(sys.argv) > 1 else "member.json") as f:
        described = json.load(f)
    member, keys = described["member"], described["keys"]
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    session = zenoh.open(zenoh.Config.from_env())
    pubs = {name: session.declare_publisher(keys[name], congestion_control=zenoh.CongestionControl.BLOCK)
            for name in "abc"}
    deadline = time.monotonic() + 10.0  # the module is up (its ready line came first); wait for the route
    while time.monotonic() < deadline and not pubs["a"].matching_status.matching:
        time.sleep(0.02)
    rates = {"a": float(member["rate_hz"]), "b": float(member["b_hz"]), "c": float(member["c_rate"])}
    start = {"a": PHASE["a"], "b": PHASE["b"], "c": float(member["c_start"])}
    lag = {"a": 0.0, "b": 0.0, "c": float(member["c_lag"])}
    seconds = float(member["seconds"])
    t0 = time.monotonic()
    wall0 = time.time()
    # (publish time, channel, seq): each message made at start + seq/rate, published lag after that
    events: list[tuple[float, str, int]] = [(start[name] + lag[name], name, 0) for name in "abc"]
    heapq.heapify(events)
    while events and not stop.is_set():
        at, name, seq = heapq.heappop(events)
        if at > seconds:
            continue
        delay = t0 + at - time.monotonic()
        if delay > 0 and stop.wait(delay):
            break
        made = at - lag[name]
        message: dict[str, Any] = {"header": {"seq": seq, "stamp": round(wall0 + made, 6)}, "v": value(name, seq)}
        pubs[name].put(json.dumps(message))
        heapq.heappush(events, (start[name] + (seq + 1) / rates[name] + lag[name], name, seq + 1))
    # The last messages leave, and the module's cycles on them end, before the run does (its end is this exit).
    stop.wait(0.2 + 2e-3 * float(member["cost_ms"][1]))
    session.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
