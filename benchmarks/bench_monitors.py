"""Monitor speed over a recorded log: messages judged per second, per invariant kind.

    python benchmarks/bench_monitors.py [--messages 50000]

Writes one real MCAP log (a small driving stack: commands, statuses and
trajectories at 100 Hz, localization at 100 Hz, obstacles and lights at
10 Hz), then checks it against one spec per kind and prints:

* ``check``: ``check_log`` end to end (decoding included, reading the file not);
* ``eval``: the MonitorSet alone, on messages decoded beforehand;
* for ``temporal``, also rtamt's online updates per second (one per sample period).

The target is >= 50k messages/s for bound and expression. Asserts nothing.
"""

from __future__ import annotations

import argparse
import math
import tempfile
import time
from pathlib import Path

from astaa_deft.io.codecs import get_codec
from astaa_deft.io.log.reader import read_log
from astaa_deft.io.log.writer import LogWriter
from astaa_deft.engine.monitor import MonitorSet, check_log, with_typed_invariants
from astaa_deft.engine.spec.loader import load_spec_text

# The driving stack the monitor tests use too (one copy, under tests/data).
BASE = (Path(__file__).resolve().parent.parent / "tests" / "data" / "driving_stack.yaml").read_text() + "invariants:\n"

KINDS = {
    "bound": ("command", """
  - {name: finite_cmd, kind: bound, channel: command, field: acceleration, finite: true, min: -8, max: 4}"""),
    "bound[*]": ("trajectory", """
  - {name: speeds, kind: bound, channel: trajectory, field: "points[*].v", min: 0, max: 40}"""),
    "expression": ("status", """
  - {name: speed_limit, kind: expression, channel: status, expr: "ego_speed <= speed_limit + 0.5 and mode == 'auto'"}"""),
    "temporal": ("localization+lights", """
  - name: stop_at_red
    kind: temporal
    period: 0.1
    signals:
      red: {channel: lights, expr: "lights[0].state == 'red'"}
      stop_x: {channel: lights, expr: "lights[0].stop_line_x"}
      ego_x: {channel: localization, field: x}
      speed: {channel: localization, field: speed}
    formula: "always((red and stop_x - ego_x >= 0 and stop_x - ego_x <= 5) implies eventually[0:2](speed < 0.5))"
"""),
    "collision": ("localization+obstacles", """
  - name: no_collision
    kind: collision
    ego: {channel: localization, length: 4.5, width: 1.9}
    obstacles: {channel: obstacles, array: obstacles, id: id}
"""),
}


def write_log(path: Path, messages: int) -> None:
    spec = load_spec_text(BASE + "  []\n")
    writer = LogWriter(path, spec)
    channel_ids = {c.name: writer.bus_channel(c) for c in spec.channels}
    codecs = {c.name: get_codec(c.encoding) for c in spec.channels}  # status is CBOR, the rest JSON

    def write(name: str, time_ns: int, value: dict) -> None:
        writer.message(channel_ids[name], time_ns, codecs[name].encode(value))

    t0 = 1_700_000_000_000_000_000
    writer.event("run_started", time_ns=t0)
    # per 10 ms step: command, status, trajectory, localization; every 10th step obstacles and lights
    steps = messages * 10 // 42
    for k in range(steps):
        t = t0 + k * 10_000_000
        header = {"seq": k, "stamp": k * 0.01}
        x = 0.1 * k
        write("command", t + 1000, (
            {"header": header, "acceleration": math.nan if k % 997 == 0 else 0.5, "steering": 0.0}))
        write("status", t + 2000, (
            {"ego_speed": 10.0 + (k % 50 == 0), "speed_limit": 10.4, "mode": "auto"}))
        write("trajectory", t + 3000, (
            {"header": header, "points": [{"t": i * 0.1, "x": x + i, "v": 10.0} for i in range(10)]}))
        write("localization", t + 4000, (
            {"header": header, "x": x % 200, "y": 0.0, "heading": 0.0, "speed": 10.0}))
        if k % 10 == 0:
            write("obstacles", t + 5000, ({"header": header, "obstacles": [
                {"id": i, "x": 20.0 * i, "y": 4.0, "heading": 0.0, "length": 4.0, "width": 2.0} for i in range(8)]
            }))
            state = "red" if (k // 500) % 2 else "green"
            write("lights", t + 6000, (
                {"header": header, "lights": [{"id": 1, "state": state, "stop_line_x": 150.0}]}))
    writer.finish()


def bench(log, kind: str, invariant: str) -> dict:
    spec = with_typed_invariants(load_spec_text(BASE + invariant))
    result = check_log(log, spec)
    # the MonitorSet alone, on values decoded beforehand (what the proxy's monitor thread does)
    monitors = MonitorSet(spec, result.start_ns)
    wanted = monitors.channels()
    routes = {topic: info.metadata["channel"] for topic, info in log.channels.items()
              if info.metadata.get("channel") in wanted}
    codecs = {ch.name: get_codec(ch.encoding) for ch in spec.channels}
    decoded = [(routes[m.topic], m.log_time, codecs[routes[m.topic]].decode(m.data), m.sequence)
               for m in log.messages if m.topic in routes]
    clock = time.perf_counter()
    for channel, t, value, seq in decoded:
        monitors.on_message(channel, t, value, seq)
    monitors.finish(result.end_ns)
    eval_seconds = time.perf_counter() - clock
    out = {"kind": kind, "messages": result.messages, "violations": len(result.violations),
           "check_per_s": result.messages / result.seconds, "eval_per_s": len(decoded) / eval_seconds}
    if kind == "temporal":
        out["samples_per_s"] = stl_samples_per_second(spec.invariants[0].formula)
    return out


def stl_samples_per_second(formula, samples: int = 20_000) -> float:
    """rtamt's online update alone: one sampled signal vector per call."""
    online = formula.online_monitor()
    values = [[(name, float(k % 7 - 3)) for name in formula.signals] for k in range(samples)]
    clock = time.perf_counter()
    for vector in values:
        online.update(vector)
    return samples / (time.perf_counter() - clock)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--messages", type=int, default=50_000, help="about how many messages the log holds")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "bench.mcap"
        clock = time.perf_counter()
        write_log(path, args.messages)
        log = read_log(path)
        print(f"log: {len(log.messages)} messages, written and read in {time.perf_counter() - clock:.2f} s")
        print(f"{'kind':11} {'channels':24} {'judged':>7} {'found':>6} {'check msg/s':>12} {'eval msg/s':>11}")
        for kind, (channels, invariant) in KINDS.items():
            r = bench(log, kind, invariant)
            extra = f"   ({r['samples_per_s']:,.0f} STL samples/s)" if "samples_per_s" in r else ""
            print(f"{kind:11} {channels:24} {r['messages']:7d} {r['violations']:6d} {r['check_per_s']:12,.0f} "
                  f"{r['eval_per_s']:11,.0f}{extra}")


if __name__ == "__main__":
    main()
