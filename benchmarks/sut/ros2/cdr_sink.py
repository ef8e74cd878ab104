"""ROS 2-style benchmark subscriber: counts, and one-way latency from the rmw_zenoh attachment's source timestamp.

Writes a JSON result to OUT once COUNT messages arrived or the stream went
quiet for 3 s after its first message; then idles until terminated.
"""

import argparse
import json
import os
import signal
import struct
import threading
import time

import zenoh

ap = argparse.ArgumentParser()
ap.add_argument("--key", required=True)
ap.add_argument("--count", type=int, default=10000)
ap.add_argument("--out", required=True)
args = ap.parse_args()

stop = threading.Event()
signal.signal(signal.SIGTERM, lambda *_: stop.set())
state = {"n": 0, "first": 0, "last": 0, "bytes": 0}
latencies = []
done = threading.Event()
stamp = struct.Struct("<q")


def on_sample(sample):
    now = time.time_ns()
    if state["n"] == 0:
        state["first"] = now
    state["n"] += 1
    state["last"] = now
    latencies.append((now - stamp.unpack_from(sample.attachment.to_bytes(), 8)[0]) / 1000.0)
    if state["n"] >= args.count:
        done.set()


session = zenoh.open(zenoh.Config.from_env())
sub = session.declare_subscriber(args.key, on_sample)
while not done.wait(0.2) and not stop.is_set():
    if state["n"] and time.time_ns() - state["last"] > 3e9:
        break
n, span = state["n"], (state["last"] - state["first"]) / 1e9
lat = sorted(latencies)
result = {"received": n, "seconds": span, "rate": (n - 1) / span if span > 0 else 0.0,
          "p50_us": lat[len(lat) // 2] if lat else None, "p99_us": lat[int(len(lat) * 0.99)] if lat else None}
with open(args.out + ".tmp", "w") as fh:
    json.dump(result, fh)
os.replace(args.out + ".tmp", args.out)
stop.wait()
sub.undeclare()
session.close()
