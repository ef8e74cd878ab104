"""A third-party-style module that ends a run: publishes a status at RATE Hz, says done after N, maybe exits.

Imports nothing from astaa-deft; finds its Zenoh config through ZENOH_CONFIG.
--exit-code C: exit with code C right after the done message; -1: keep
publishing (done stays true) until terminated.
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
ap.add_argument("--rate", type=float, default=20.0)
ap.add_argument("--done-after", type=int, default=10)
ap.add_argument("--exit-code", type=int, default=-1)
args = ap.parse_args()

stop = threading.Event()
signal.signal(signal.SIGTERM, lambda *_: stop.set())
signal.signal(signal.SIGINT, lambda *_: stop.set())

session = zenoh.open(zenoh.Config.from_env())
pub = session.declare_publisher(args.key)
time.sleep(0.3)
i = 0
while not stop.is_set():
    i += 1
    done = i >= args.done_after
    pub.put(json.dumps({"header": {"seq": i, "stamp": time.time()}, "done": done, "count": i}).encode())
    if done and args.exit_code >= 0:
        time.sleep(0.05)
        session.close()
        sys.exit(args.exit_code)
    stop.wait(1.0 / args.rate)
session.close()
