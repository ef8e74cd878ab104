"""Benchmark publisher (third-party style: only zenoh, config from ZENOH_CONFIG).

Sends COUNT JSON messages of SIZE bytes on KEY, as fast as possible
(--rate 0) or at RATE Hz; each carries its sequence number and send time.
"""

import argparse
import json
import signal
import threading
import time

import zenoh

ap = argparse.ArgumentParser()
ap.add_argument("--key", default="bench/data")
ap.add_argument("--size", type=int, default=200)
ap.add_argument("--count", type=int, default=100000)
ap.add_argument("--rate", type=float, default=0.0)
ap.add_argument("--start-delay", type=float, default=1.0)
args = ap.parse_args()

stop = threading.Event()
signal.signal(signal.SIGTERM, lambda *_: stop.set())

session = zenoh.open(zenoh.Config.from_env())
pub = session.declare_publisher(args.key, congestion_control=zenoh.CongestionControl.BLOCK)
time.sleep(args.start_delay)
template = json.dumps({"header": {"seq": 0, "stamp": 0}, "value": 0.5, "pad": ""})
pad = "x" * max(0, args.size - len(template) - 30)
period = 1.0 / args.rate if args.rate else 0.0
next_t = time.monotonic()
for i in range(1, args.count + 1):
    if stop.is_set():
        break
    body = '{"header": {"seq": %d, "stamp": %d}, "value": 0.5, "pad": "%s"}' % (i, time.time_ns(), pad)
    pub.put(body.encode())
    if period:
        next_t += period
        delay = next_t - time.monotonic()
        if delay > 0:
            time.sleep(delay)
stop.wait()
session.close()
