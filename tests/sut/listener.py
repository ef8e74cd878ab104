"""A third-party-style Zenoh subscriber: imports nothing from astaa-deft.

Writes one line per received message to OUT: key, payload hex, attachment hex.
"""

import argparse
import signal
import threading

import zenoh

ap = argparse.ArgumentParser()
ap.add_argument("--key", action="append", required=True)
ap.add_argument("--out", required=True)
args = ap.parse_args()

stop = threading.Event()
signal.signal(signal.SIGTERM, lambda *_: stop.set())
signal.signal(signal.SIGINT, lambda *_: stop.set())

out = open(args.out, "w", buffering=1)
lock = threading.Lock()


def on_sample(sample):
    att = sample.attachment.to_bytes().hex() if sample.attachment is not None else "-"
    with lock:
        out.write(f"{sample.key_expr} {sample.payload.to_bytes().hex()} {att}\n")


session = zenoh.open(zenoh.Config.from_env())
subs = [session.declare_subscriber(k, on_sample) for k in args.key]
print("listener: subscribed", flush=True)
stop.wait()
for s in subs:
    s.undeclare()
session.close()
out.close()
