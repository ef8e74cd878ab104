"""A third-party-style Zenoh publisher: imports nothing from astaa-deft.

It finds its session config only through zenoh.Config.from_env()
(ZENOH_CONFIG), publishes COUNT messages on KEY at RATE Hz, then idles until
terminated (so the run, not the module, decides when to stop).
"""

import argparse
import json
import signal
import sys
import threading
import time

import zenoh

ap = argparse.ArgumentParser()
ap.add_argument("--key", required=True)
ap.add_argument("--rate", type=float, default=100.0)
ap.add_argument("--count", type=int, default=100)
ap.add_argument("--start-delay", type=float, default=0.5)
ap.add_argument("--garbage-every", type=int, default=0, help="every N-th payload is not JSON")
ap.add_argument("--extra-key", default="", help="also publish each message on this (undeclared) key")
ap.add_argument("--crash-after", type=int, default=0, help="exit with code 3 after N messages")
ap.add_argument("--spawn-child", action="store_true", help="start a sleeping child (tests process-group cleanup)")
ap.add_argument("rest", nargs="*", help="ignored (lets a spec pass an empty optional flag)")
args = ap.parse_args()

stop = threading.Event()
signal.signal(signal.SIGTERM, lambda *_: stop.set())
signal.signal(signal.SIGINT, lambda *_: stop.set())

if args.spawn_child:
    import subprocess

    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(600)"])
    print(f"talker: child pid {child.pid}", flush=True)

session = zenoh.open(zenoh.Config.from_env())
pub = session.declare_publisher(args.key, congestion_control=zenoh.CongestionControl.BLOCK)
extra = session.declare_publisher(args.extra_key) if args.extra_key else None
time.sleep(args.start_delay)
period = 1.0 / args.rate
next_t = time.monotonic()
for i in range(1, args.count + 1):
    if stop.is_set():
        break
    if args.garbage_every and i % args.garbage_every == 0:
        payload = b"\xff\x00not json" + bytes([i % 256])
    else:
        payload = json.dumps({"header": {"seq": i, "stamp": time.time()}, "value": i * 0.5}).encode()
    pub.put(payload, encoding=zenoh.Encoding.APPLICATION_JSON, attachment=f"seq={i}".encode())
    if extra is not None:
        extra.put(payload)
    if args.crash_after and i >= args.crash_after:
        sys.stderr.write("talker: simulated crash\n")
        sys.stderr.flush()
        session.close()
        sys.exit(3)
    next_t += period
    delay = next_t - time.monotonic()
    if delay > 0:
        time.sleep(delay)
print("talker: done", flush=True)
stop.wait()
session.close()
